"""``[[output]] at = "equilibrium"``: static accuracy against closed forms. A bar hanging
from a pin of clearance c sags by exactly c; a two-bar chain with a horizontal tip load
keeps the ideal chain's angles, its journals lying along the forces through the joints, so
its tip moves by c₁ u₁ + c₂ u₂ (u the unit directions of those forces)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mcchain.scene import compile_model, load_scene_text
from mcchain.solvers import solve_chunk
from mcchain.testing.closed_forms import G
from mcchain.testing.factory import clearance_bar_text

STATIC_TOLERANCE = 1e-12
"""m: the issue's bound; two Newton equilibria, each converged to rounding."""


def _tip_outputs(body: str, tip: float, components=("x", "y", "magnitude")) -> str:
    return "".join(
        f"""
[[output]]
name = "tip_{c}"
of = "position"
body = "{body}"
point = [{tip!r}, 0.0]
component = "{c}"
relative_to = "ideal"
at = "equilibrium"
"""
        for c in components
    )


def test_hanging_bar__sags_by_the_clearance():
    clearances = [1e-4, 3e-4, 1e-3]
    text = clearance_bar_text(clearance=1e-3, modes=False)
    text += "\n[sample]\ncount = 3\n[sample.vary]\n"
    text += f'"joint.O.clearance" = {{ choice = {clearances!r} }}\n'
    text += _tip_outputs("bar", 0.5)
    text += """
[[output]]
name = "angle"
of = "angle"
body = "bar"
relative_to = "ideal"
at = "equilibrium"
[[output]]
name = "pin_force"
of = "joint_force"
joint = "O"
component = "y"
at = "equilibrium"
"""
    scene = load_scene_text(text)
    model = compile_model(scene)
    out = solve_chunk(model, scene)
    c = np.asarray(model.joint_clearance)[:, 0]
    assert np.max(np.abs(out["tip_y"] + c)) <= STATIC_TOLERANCE
    assert np.max(np.abs(out["tip_x"])) <= STATIC_TOLERANCE
    assert np.max(np.abs(out["tip_magnitude"] - c)) <= STATIC_TOLERANCE
    assert np.max(np.abs(out["angle"])) <= 1e-12
    assert out["pin_force"] == pytest.approx(np.full(3, 2.0 * G), rel=1e-12)  # holds m g


def _chain_text(m1: float, m2: float, length: float, c1: float, c2: float, load: float) -> str:
    half = length / 2
    inertia = [m * length**2 / 12 for m in (m1, m2)]
    return f"""
[[body]]
name = "upper"
mass = {m1!r}
inertia = {inertia[0]!r}
position = [0.0, {-half!r}]
angle = {-math.pi / 2!r}
[[body]]
name = "lower"
mass = {m2!r}
inertia = {inertia[1]!r}
position = [0.0, {-3 * half!r}]
angle = {-math.pi / 2!r}
[[joint]]
name = "O"
bodies = ["ground", "upper"]
points = [[0.0, 0.0], [{-half!r}, 0.0]]
clearance = {c1!r}
[[joint]]
name = "K"
bodies = ["upper", "lower"]
points = [[{half!r}, 0.0], [{-half!r}, 0.0]]
clearance = {c2!r}
[[force]]
name = "P"
body = "lower"
point = [{half!r}, 0.0]
value = [{load!r}, 0.0]
[equilibrium]
""" + _tip_outputs("lower", half)


@pytest.mark.parametrize("load", [0.0, 3.0, -40.0])
def test_two_bar_chain__tip_against_the_closed_form(load):
    m1, m2, length, c1, c2 = 1.5, 0.8, 0.6, 2e-4, 5e-4
    scene = load_scene_text(_chain_text(m1, m2, length, c1, c2, load))
    out = solve_chunk(compile_model(scene), scene)
    # the force on each journal body by its bearing balances what hangs below it; the
    # journal lies against the wall opposite to it
    below_o = np.array([load, -(m1 + m2) * G])
    below_k = np.array([load, -m2 * G])
    expected = c1 * below_o / np.hypot(*below_o) + c2 * below_k / np.hypot(*below_k)
    assert abs(out["tip_x"][0] - expected[0]) <= STATIC_TOLERANCE
    assert abs(out["tip_y"][0] - expected[1]) <= STATIC_TOLERANCE
    assert abs(out["tip_magnitude"][0] - np.hypot(*expected)) <= STATIC_TOLERANCE


def test_rare__an_output_at_the_equilibrium_through_the_solvers(
    tmp_path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``mcchain rare`` re-solves an output with the scene's kernels: the hanging bar's sag
    relative to the ideal bar is −c, so "sag ≥ −L" fails where c > L; subset simulation on
    the kernels gives the estimate it gives on the closed form −c(u) (same seed)."""
    import csv

    from scipy.special import ndtr

    from mcchain.cli import main
    from mcchain.decision.rare import margin
    from mcchain.decision.subset import subset_simulation

    low, high, limit, per_level = 1e-4, 1e-3, 9.991e-4, 200  # P(c > limit) = 1e-3
    text = clearance_bar_text(clearance=5e-4, modes=False)
    text += '\n[sample]\ncount = 8\nseed = 4\n[sample.vary]\n"joint.O.clearance" = '
    text += f"{{ uniform = [{low!r}, {high!r}] }}\n" + _tip_outputs("bar", 0.5, ("y",))
    text += f'\n[[requirement]]\nname = "sag"\noutput = "tip_y"\nmin = {-limit!r}\n'
    scene = tmp_path / "bar.toml"
    scene.write_text(text, encoding="utf-8")
    folder = tmp_path / "rare"
    argv = ["rare", str(scene), "--requirement", "sag", "--per-level", str(per_level),
            "--run-dir", str(folder)]  # fmt: skip
    assert main(argv) == 0
    assert "P(fail) = " in capsys.readouterr().out
    with open(folder / "export" / "subset.csv", encoding="utf-8") as f:
        (found,) = list(csv.DictReader(f))

    def closed_form(u: np.ndarray) -> np.ndarray:
        c = low + np.clip(ndtr(u[:, 0]), 2.0**-53, 1 - 2.0**-53) * (high - low)
        return margin(-c, -limit, None)

    reference = subset_simulation(closed_form, 1, per_level=per_level, seed=4)
    assert float(found["p_fail"]) == pytest.approx(reference.p_fail, rel=1e-12)
    assert 2e-4 < reference.p_fail < 5e-3  # the exact 1e-3, within the estimate's spread
