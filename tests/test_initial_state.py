"""Initial states that just work: a mechanism written with its dimensions only.

The driven four-bar of ``configs/fourbar-clearance.toml`` written without any position,
angle, velocity or eccentricity (only masses, joint points, the driver and the clearance)
must assemble on the open branch at the driver's angle (closed-form position and velocity
analysis), press its clearance journal on the bearing wall the way the ideal mechanism's
joint force says (an independent dense KKT solve), and start in contact in every sample.
Written inputs that assembly moves are reported, one line per body.
"""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from mcchain.cli import main
from mcchain.kernels.joints import joint_separation_rate, joint_vectors
from mcchain.runner.job import default_loader
from mcchain.scene import compile_model, load_scene_text
from mcchain.solvers.simulate import simulate
from mcchain.solvers.statics import (
    assemble,
    initial_state_warnings,
    start_multipliers,
    written_state,
)
from mcchain.testing import dense
from mcchain.testing.factory import write_scene
from mcchain.testing.scenes import fourbar_text

CRANK, COUPLER, ROCKER, GROUND_LINK = 0.1, 0.3, 0.25, 0.3
PHI = np.pi / 3  # the driver's angle at t = 0
OMEGA = 20.0


def dimensions_only(clearance: float = 1e-4, sample: str = "") -> str:
    """The shipped four-bar with every body state line removed and angle0 on the driver."""
    text = fourbar_text()
    text = re.sub(r"^(position|angle|velocity|angular_velocity) = .*\n", "", text, flags=re.M)
    text = text.replace("clearance = 1e-4", f"clearance = {clearance!r}")
    text = text.replace("omega = 20.0", f"omega = 20.0\nangle0 = {PHI!r}")
    assert "position" not in text and "velocity" not in text
    return text + sample


def closed_form_fourbar() -> tuple[np.ndarray, np.ndarray]:
    """q, v (9,) of the ideal four-bar, open branch (B above the line A–O4), from circle
    intersection and the differentiated loop closure."""
    a = CRANK * np.array([np.cos(PHI), np.sin(PHI)])
    o4 = np.array([GROUND_LINK, 0.0])
    chord = o4 - a
    dist = np.hypot(*chord)
    along = (COUPLER**2 - ROCKER**2 + dist**2) / (2 * dist)
    height = np.sqrt(COUPLER**2 - along**2)
    normal = np.array([-chord[1], chord[0]]) / dist
    b = a + along * chord / dist + height * normal
    th2 = np.arctan2(*(b - a)[::-1])
    th3 = np.arctan2(*(b - o4)[::-1])
    e2, e3 = np.array([np.cos(th2), np.sin(th2)]), np.array([np.cos(th3), np.sin(th3)])
    q = np.concatenate([a / 2, [PHI], a + e2 * COUPLER / 2, [th2], o4 + e3 * ROCKER / 2, [th3]])

    def perp(th: float) -> np.ndarray:
        return np.array([-np.sin(th), np.cos(th)])

    # a ω1 perp(φ) + b ω2 perp(θ2) − c ω3 perp(θ3) = 0
    w2, w3 = np.linalg.solve(
        np.column_stack([COUPLER * perp(th2), -ROCKER * perp(th3)]), -CRANK * OMEGA * perp(PHI)
    )
    va = CRANK * OMEGA * perp(PHI)
    v = np.concatenate(
        [
            va / 2,
            [OMEGA],
            va + w2 * COUPLER / 2 * perp(th2),
            [w2],
            w3 * ROCKER / 2 * perp(th3),
            [w3],
        ]
    )
    return q, v


def test_dimensions_only__ideal_fourbar_assembles_on_the_open_branch_with_velocity_analysis():
    model = compile_model(load_scene_text(dimensions_only(clearance=0.0)))
    assembled = assemble(model)
    q, v = closed_form_fourbar()
    assert assembled.status[0] == 0
    np.testing.assert_allclose(assembled.q[0], q, rtol=0, atol=1e-12)
    np.testing.assert_allclose(assembled.v[0], v, rtol=0, atol=1e-10)


def test_dimensions_only__unwritten_positions_are_walked_over_the_joints():
    model = compile_model(load_scene_text(dimensions_only()))
    a = CRANK * np.array([np.cos(PHI), np.sin(PHI)])
    # crank at the driver's angle about O2; coupler at angle 0 from A; rocker at angle 0
    # hung from the coupler's B (joint B comes before O4 in the file)
    expected = [a[0] / 2, a[1] / 2, PHI, a[0] + 0.15, a[1], 0.0, a[0] + 0.175, a[1], 0.0]
    np.testing.assert_allclose(model.q0[0], expected, rtol=0, atol=1e-15)
    assert model.driver_angle0[0, 0] == PHI


def test_dimensions_only__journal_pressed_where_the_ideal_force_says_and_at_rest():
    """Per sample: |d| = c; d opposite to the ideal mechanism's force on the journal (dense
    KKT at the ideal assembly); ḋ = 0; λ > 0 at t = 0; positions within about c of the ideal."""
    sample = '[sample]\ncount = 8\nseed = 3\n[sample.vary]\n"joint.B.clearance" = '
    sample += "{ uniform = [5e-5, 2e-4] }\n"
    model = compile_model(load_scene_text(dimensions_only(sample=sample)))
    ideal = compile_model(load_scene_text(dimensions_only(clearance=0.0)))
    q_ideal, v_ideal = closed_form_fourbar()
    _, lam_ideal = dense.kkt_acceleration(ideal, 0, q_ideal, v_ideal, 0.0)
    force_on_journal = -lam_ideal[4:6]  # joint B: rows 4, 5 of the ideal model
    expected_direction = np.arctan2(*(-force_on_journal)[::-1])
    assembled = assemble(model)
    km = model.kernel_model()
    assert not assembled.status.any()
    for s in range(model.nsample):
        q, v = assembled.q[s], assembled.v[s]
        pax, pay, pbx, pby, dx, dy = joint_vectors(km, s, q, 2)
        c = model.joint_clearance[s, 2]
        assert abs(np.hypot(dx, dy) - c) <= 1e-15
        assert abs(np.arctan2(dy, dx) - expected_direction) <= 1e-9
        rate = joint_separation_rate(v, 1, 2, pax, pay, pbx, pby)
        assert np.hypot(*rate) <= 1e-12
        moved = np.abs(q - q_ideal).reshape(3, 3)
        assert moved[:, :2].max() <= 2 * c and moved[:, 2].max() <= 2 * c / 0.125
        lam = start_multipliers(model, q, v, sample=s)
        assert lam[int(model.joint_row[2])] > 0.5 * np.hypot(*force_on_journal)


def test_dimensions_only__no_sample_loses_contact_at_the_start():
    sample = '[sample]\ncount = 64\nseed = 5\n[sample.vary]\n"joint.B.clearance" = '
    sample += "{ uniform = [5e-5, 2e-4] }\n"
    model = compile_model(load_scene_text(dimensions_only(sample=sample)))
    assembled = assemble(model)
    out = simulate(
        model,
        dict(t_end=0.01, dt=1e-5, output_dt=1e-3),
        q_start=assembled.q,
        v_start=assembled.v,
        history_dtype=np.float64,
    )
    assert not out["status"].any()
    force = out["contact_force"][:, :, 2]
    assert (force[:, 0] > 6.5).all()  # the link pushes with 6.57 N at t = 0 in every sample
    assert (force > 3.0).all()  # and still over the first 10 ms (it lets go near 0.25 s)


def test_warnings__a_written_position_moved_far_is_named_with_its_distance():
    text = fourbar_text().replace(
        "position = [0.30085606180870794, 0.12499706859834622]", "position = [3.3, 1.2]"
    )
    written, assembled = written_state(load_scene_text(text))
    lines = initial_state_warnings(written, assembled)
    # every written body moved is named, whatever its size: the coupler follows by 3e-8 m
    assert [line.split(":")[0] for line in lines] == ["body.coupler", "body.rocker"]
    move = np.hypot(3.3 - 0.30085606180870794, 1.2 - 0.12499706859834622)
    assert lines[1].startswith(f"body.rocker: assembly moved it by {move:.3g} m")
    coupler = np.hypot(*(assembled.q[0, 3:5] - written.q0[0, 3:5]))
    assert 1e-9 < coupler < 1e-6 and f"(centre {coupler:.3g} m" in lines[0]


def test_warnings__written_velocities_corrected_are_named():
    text = fourbar_text().replace(
        "velocity = [-0.8660254037844386, 0.5000000000000002]", "velocity = [0.0, 0.5]"
    )
    lines = initial_state_warnings(*written_state(load_scene_text(text)))
    assert len(lines) == 1
    assert lines[0].startswith("body.crank: assembly changed its written velocity by 0.866 m/s")


@pytest.mark.parametrize("text", [fourbar_text(), dimensions_only()], ids=["written", "dims"])
def test_warnings__consistent_or_unwritten_states_are_silent(text):
    assert initial_state_warnings(*written_state(load_scene_text(text))) == []


def test_validate__prints_the_assembled_state_and_the_warnings(tmp_path, capsys):
    text = fourbar_text().replace(
        "position = [0.30085606180870794, 0.12499706859834622]", "position = [3.3, 1.2]"
    )
    assert main(["validate", str(write_scene(tmp_path, text))]) == 0
    out = capsys.readouterr().out
    assert "initial state at t = 0 (assembled):" in out
    assert re.search(
        r"B: \|d\| 0\.0001 m at 0\.95\d+ rad \(eccentricity\), \|d\| - c \S+ m; starts on "
        r"the link: link force 6\.5",
        out,
    )
    assert "contact holds" in out
    assert "warning: body.rocker: assembly moved it by 3.19 m" in out


def test_run__records_the_warnings_in_run_json(tmp_path, capsys):
    text = fourbar_text().replace(
        "position = [0.30085606180870794, 0.12499706859834622]", "position = [3.3, 1.2]"
    )
    path = write_scene(tmp_path, text + "[equilibrium]\n")
    assert main(["run", str(path), "--out", str(tmp_path / "runs"), "--quiet"]) == 0
    captured = capsys.readouterr()
    assert "warning: body.rocker: assembly moved it" in captured.err
    folder = next((tmp_path / "runs").iterdir())
    record = json.loads((folder / "run.json").read_text())
    assert [w.split(":")[0] for w in record["warnings"]] == ["body.coupler", "body.rocker"]
    _, model = default_loader(path, None, None)
    assert model.meta["warnings"] == record["warnings"]
