"""rk45's stored times from its steps' continuous extension (Shampine's quartic interpolant
of Dormand–Prince): the output grid changes no step and no per-sample value, a stored
point is the same whatever grid it is on, the interpolated state is as accurate as the
steps, and its reactions are the accelerations' there."""

from __future__ import annotations

import numpy as np
import pytest

from mcchain.scene import compile_model, load_scene_text
from mcchain.solvers.output_plan import output_plan
from mcchain.solvers.simulate import simulate
from mcchain.solvers.statics import assemble
from mcchain.testing.scenes import config_text, flores_pin_text, with_lines

HISTORY_KEYS = frozenset(
    ("q", "v", "joint_force", "contact_force", "driver_torque", "driver_force", "joint_moment",
     "constraint_error", "energy", "penetration", "contact_mode")
)  # fmt: skip


def pin_runs(output_dts: list[float]) -> list[dict[str, np.ndarray]]:
    """The Flores slider-crank with its piston pin's impacts (four clearances, one sample
    failed on entry), 12 ms by rk45 at rtol 1e-8, with an output, once per output step."""
    from dataclasses import replace

    from mcchain.status import ASSEMBLY_FAILED

    runs = []
    for output_dt in output_dts:
        text = flores_pin_text(t_end=0.012, method="rk45", rtol=1e-8, atol=1e-11)
        text = with_lines(text, {"output_dt": f"output_dt = {output_dt!r}", "dt": "dt = 1e-7"})
        text += '\n[[output]]\nname = "pin"\nof = "joint_force"\njoint = "B"\n'
        text += 'component = "magnitude"\nreduce = "max"\n'
        scene = load_scene_text(text)
        model = compile_model(scene, nsample=5)
        clearance = np.array(model.joint_clearance, dtype=float)
        clearance = np.broadcast_to(clearance, (5, clearance.shape[-1])).copy()
        clearance[:, 2] = [1e-4, 2e-4, 5e-4, 3e-4, 4e-4]
        model = replace(model, joint_clearance=clearance)
        start = assemble(model)
        status = start.status.copy()
        status[3] |= ASSEMBLY_FAILED
        plan = output_plan(scene.output, model, scene.simulate.t_end)
        runs.append(
            simulate(model, scene.simulate, start.q, start.v, np.float64, status=status,
                     diagnostics=True, outputs=plan)
        )  # fmt: skip
    return runs


@pytest.fixture(scope="module")
def pin() -> list[dict[str, np.ndarray]]:
    # 1e-4: a point every few steps; 1e-5 and 3.3e-5 (no whole number of them in 12 ms):
    # about one a step; 1e-6: many a step (the queue of points full, rounds forced)
    return pin_runs([1e-4, 1e-5, 3.3e-5, 1e-6])


def test_rk45__the_output_grid_changes_no_per_sample_value(pin) -> None:
    """Status, steps, rejected steps, evaluations, peaks, contact summaries and outputs are
    bitwise the same on every grid, the pin's impacts included."""
    first, *others = pin
    assert first["impact_count"][:3].max() > 0  # the pin's journal did hit its bearing
    for other in others:
        assert set(other) == set(first)
        for key, value in first.items():
            if key in HISTORY_KEYS or key == "time":
                continue
            assert other[key].tobytes() == value.tobytes(), key


def test_rk45__a_stored_point_is_the_same_on_every_grid(pin) -> None:
    """At the times two grids share, every history is bitwise the same: a point's state
    and reactions come from its step alone (not from the lanes beside it, nor from when
    its queue was evaluated); a failed sample's history is NaN on every grid."""
    first, *others = pin
    for other in others:
        common, i, j = np.intersect1d(first["time"], other["time"], return_indices=True)
        assert len(common) >= 2  # 0 and t_end at least; 1e-5 and 1e-6 share many more
        for key in HISTORY_KEYS & set(first):
            a, b = first[key][:, i], other[key][:, j]
            assert a.tobytes() == b.tobytes(), key
        assert np.isnan(other["q"][3]).all() and np.isfinite(other["q"][[0, 1, 2, 4]]).all()


def ideal_slider_crank(method: str, output_dt: float, **settings: float) -> dict:
    """The Flores slider-crank with its pin ideal, 6 ms, by ``method``."""
    text = config_text("slider-crank-flores.toml").split("[sample]")[0]
    dropped = ("clearance", "model", "[joint.contact]", "law", "restitution", "radius",
               "youngs_modulus", "poisson_ratio")  # fmt: skip
    lines = {key: "" for key in dropped}
    keys = {"method": f'"{method}"', "t_end": "0.006", "output_dt": repr(output_dt)}
    keys |= {k: repr(v) for k, v in settings.items()}
    lines |= {k: f"{k} = {v}" for k, v in keys.items()}
    scene = load_scene_text(with_lines(text, lines))
    model = compile_model(scene, nsample=1)
    start = assemble(model)
    return simulate(model, scene.simulate, start.q, start.v, np.float64, status=start.status)


def test_rk45__dense_state_is_as_accurate_as_the_steps() -> None:
    """The slider's x at every stored time (most inside a step) against the closed form of
    the ideal slider-crank driven at constant speed, x = r cos θ + √(l² − r² sin² θ): within
    1e-10 of the 0.17 m stroke's end at rtol 1e-10, as at the steps' ends."""
    run = ideal_slider_crank("rk45", 1e-5, rtol=1e-10, atol=1e-13, dt=1e-7)
    t = run["time"]
    theta = 523.5987755982989 * t  # angle0 = 0
    r, length = 0.05, 0.12
    x = r * np.cos(theta) + np.sqrt(length**2 - (r * np.sin(theta)) ** 2)
    slider = run["q"][0].reshape(len(t), -1)[:, 6]
    assert np.abs(slider - x).max() < 1e-10 * 0.17


def test_rk45__dense_reactions_are_those_of_the_state() -> None:
    """Joint forces and the driver's torque at the stored times (inside rk45's steps, from
    one evaluation at the interpolated state) against rk4 landing on every one with a
    step of 1e-7 s: the same to 1e-7 of their largest."""
    dense = ideal_slider_crank("rk45", 1e-5, rtol=1e-10, atol=1e-13, dt=1e-7)
    fixed = ideal_slider_crank("rk4", 1e-5, dt=1e-7)
    assert dense["time"].tobytes() == fixed["time"].tobytes()
    for key in ("joint_force", "driver_torque"):
        a, b = dense[key], fixed[key]
        assert np.abs(a - b).max() < 1e-7 * np.abs(b).max(), key
