"""The loop kernels (``[simulate] kernels = "loop"``, one compile for every topology) against
the generated lane kernels: the same RK4 steps, checks and outputs, to 1e-12."""

from __future__ import annotations

import numpy as np
import pytest
from test_cli_commands import assert_usage_error, in_process

from mcchain.scene import compile_model, load_scene_text
from mcchain.solvers.simulate import simulate
from mcchain.solvers.statics import assemble
from mcchain.status import CONTACT_LOST, CONTACT_STEP_TOO_LARGE
from mcchain.testing import dense
from mcchain.testing.factory import write_scene
from mcchain.testing.scenes import scene_model, straight_chain_text

AGREEMENT = 1e-12
"""Largest difference between the two paths, relative to each output's largest value."""
HISTORIES = ("q", "v", "joint_force", "contact_force", "driver_torque", "energy")

CHAIN = straight_chain_text([0.5, 0.4, 0.3, 0.45, 0.35, 0.25], [1.0, 0.8, 0.6, 0.9, 0.7, 0.5])


def _both(model, **extra):
    start = assemble(model)
    sim = dict(t_end=0.05, dt=1e-5, output_dt=1e-3, method="rk4", **extra)
    return {
        kernels: simulate(
            model, dict(sim, kernels=kernels), q_start=start.q, v_start=start.v,
            history_dtype=np.float64,
        )
        for kernels in ("lanes", "loop")
    }  # fmt: skip


@pytest.mark.parametrize("name", ["chain", "fourbar", "double_pendulum"])
def test_loop__agrees_with_the_lanes(name):
    chain = compile_model(load_scene_text(CHAIN))
    model = chain if name == "chain" else scene_model(name, nsample=3)
    out = _both(model)
    lanes, loop = out["lanes"], out["loop"]
    np.testing.assert_array_equal(lanes["status"], loop["status"])
    np.testing.assert_array_equal(lanes["time"], loop["time"])
    for var in (*HISTORIES, "peak_joint_force", "peak_driver_torque"):
        a, b = lanes[var], loop[var]
        np.testing.assert_array_equal(np.isnan(a), np.isnan(b), err_msg=var)
        if np.isfinite(a).any():
            scale = np.nanmax(np.abs(a))
            assert np.nanmax(np.abs(a - b)) <= AGREEMENT * scale, var
    # the constraint error is rounding noise on both paths: compare it to the size
    assert np.nanmax(np.abs(lanes["constraint_error"] - loop["constraint_error"])) <= 1e-12


def test_loop__flags_and_fails_as_the_lanes():
    """A start far off the joints diverges at t = 0 on both paths, with NaN histories."""
    model = scene_model("double_pendulum", nsample=2)
    start = assemble(model)
    q = start.q.copy()
    q[1, 0] += 0.01  # sample 1 starts 1 cm off its joint: past the tolerance
    sim = dict(t_end=0.01, dt=1e-5, output_dt=1e-3, method="rk4")
    runs = [
        simulate(model, dict(sim, kernels=k), q_start=q, v_start=start.v, history_dtype=np.float64)
        for k in ("lanes", "loop")
    ]
    for out in runs:
        assert out["status"][0] == 0 and out["status"][1] != 0
        assert np.isnan(out["q"][1]).all() and out["diverged_time"][1] == 0.0
    np.testing.assert_array_equal(runs[0]["status"], runs[1]["status"])


def test_loop__refuses_a_method_it_does_not_have(tmp_path, monkeypatch, capsys):
    text = CHAIN + '[simulate]\nt_end = 0.01\ndt = 1e-4\nkernels = "loop"\nmethod = "rk45"\n'
    ran = in_process(monkeypatch, capsys)("validate", write_scene(tmp_path, text), cwd=tmp_path)
    assert_usage_error(ran, "simulate.kernels: \"loop\" integrates with rk4, not 'rk45'")


CONTACT_AGREEMENT = 1e-11
"""Largest difference between the paths under the contact law, relative to each output's
largest value: the impact forces (1e2–1e3 × the link's) carry the rounding of the
penetration (K δ^1.5 with δ ~ 1e-6 m)."""
RESEAT_AGREEMENT = 1e-10
"""The same under model auto over 0.3 s (150,000 steps, the switches and re-seats): there the
loop kernel against itself, the start's sideways speed 1 ulp apart, moves v by 1.2e-11 of its
largest value, the joint and contact forces by 1.9e-11 and 2.0e-11 (measured; 3 ulp: 1.0e-11,
1.3e-11, 1.4e-11), so two roundings of the step are this far apart by chance; 5× that."""
CONTACT_OUTPUTS = (
    "penetration", "peak_contact_force", "max_penetration", "free_flight_time",
    "first_separation_time", "peak_joint_force",
)  # fmt: skip


def _journal_runs(**scene):
    from test_contact_dynamics import journal_scene, run

    text = journal_scene(method="rk4", output_dt=1e-3, **scene)
    return run(text, kernels="lanes"), run(text, kernels="loop")


@pytest.mark.parametrize(
    "scene",
    [
        dict(law="hertz", model="contact", dt=2e-6, t_end=0.05),
        dict(law="flores", restitution=0.8, friction=0.1, model="contact", dt=2e-6, t_end=0.05),
        dict(law="lankarani-nikravesh", restitution=0.5, model="auto", dt=2e-6, t_end=0.3),
    ],
    ids=["hertz", "flores-friction", "auto-reseat"],
)
def test_loop__contact_law_agrees_with_the_lanes(scene):
    """The journal falling across its bearing: impacts located in the step, free flight,
    friction, the switch of model auto at λ ≤ 0 and its re-seats, on both paths."""
    lanes, loop = _journal_runs(**scene)
    assert lanes["status"][0] == 0 and loop["status"][0] == 0
    np.testing.assert_array_equal(lanes["contact_mode"], loop["contact_mode"])
    np.testing.assert_array_equal(lanes["impact_count"], loop["impact_count"])
    assert lanes["impact_count"][0, 0] >= 3
    if scene["model"] == "auto":
        mode = loop["contact_mode"][0, :, 0]
        assert np.any((mode[:-1] >= 1) & (mode[1:] == 0)), "no re-seat to compare"
    agreement = RESEAT_AGREEMENT if scene["model"] == "auto" else CONTACT_AGREEMENT
    for var in (*HISTORIES[:4], "energy", *CONTACT_OUTPUTS):
        a, b = lanes[var], loop[var]
        np.testing.assert_array_equal(np.isnan(a), np.isnan(b), err_msg=var)
        scale = np.nanmax(np.abs(a)) if np.isfinite(a).any() else 0.0
        assert np.nanmax(np.abs(a - b), initial=0.0) <= agreement * scale, var


def test_two_coupled_contact_joints__both_paths_agree_and_conserve_energy():
    """A hanging two-bar chain with a clearance under the Hertz law at both pins (their rows
    share the upper bar, so their law rows couple in S): both bars rattle in their bearings,
    the paths agree and the energy (elastic included) is conserved. The lanes once moved one
    law row's coupling into the other's λ_r = F_n and flagged the sample; the loop kernels,
    written apart from the code generator, caught it."""
    text = straight_chain_text([0.3, 0.2], [0.5, 0.3], angle=-1.2, clearance={0: 2e-4, 1: 2e-4})
    law = 'model = "contact"\n[joint.contact]\nlaw = "hertz"\nstiffness = 1e9\n'
    text = text.replace("clearance = 0.0002\n", "clearance = 0.0002\n" + law)
    model = compile_model(load_scene_text(text))
    start = assemble(model)
    sim = dict(t_end=0.05, dt=1e-6, output_dt=1e-3, method="rk4")
    lanes, loop = (
        simulate(
            model, dict(sim, kernels=k), q_start=start.q, v_start=start.v,
            history_dtype=np.float64,
        )
        for k in ("lanes", "loop")
    )  # fmt: skip
    for out in (lanes, loop):
        assert out["status"][0] == 0
        assert np.all(out["impact_count"][0] >= 5)
        energy = out["energy"][0]
        assert np.max(np.abs(energy - energy[0])) <= 1e-11 * np.max(np.abs(energy))
    np.testing.assert_array_equal(lanes["impact_count"], loop["impact_count"])
    np.testing.assert_array_equal(lanes["contact_mode"], loop["contact_mode"])
    scale = np.max(np.abs(lanes["q"]))
    assert np.max(np.abs(lanes["q"] - loop["q"])) <= 1e-12 * scale
    # 30 impacts amplify the rounding of the penetration (K δ^1.5, δ ~ 1e-6 m)
    peak = np.max(lanes["contact_force"])
    assert np.max(np.abs(lanes["contact_force"] - loop["contact_force"])) <= 1e-8 * peak


def test_loop__flags_a_step_too_large_for_the_contact_as_the_lanes():
    lanes, loop = _journal_runs(model="auto", dt=5e-4, t_end=0.05)
    for out in (lanes, loop):
        assert out["status"][0] & CONTACT_STEP_TOO_LARGE
        assert np.isnan(out["q"][0, -1]).all() and np.isnan(out["penetration"][0, -1]).all()
        assert out["impact_count"][0, 0] == -1
    np.testing.assert_array_equal(lanes["contact_mode"], loop["contact_mode"])


def test_loop__auto_equals_the_link_bit_for_bit_until_the_link_lets_go():
    """On the loop path one compiled kernel serves both models, and a joint of model auto
    runs the link's arithmetic (the law's terms are skipped, not multiplied by 0) until its λ
    first reaches 0: every output before that is bit-identical."""
    from test_contact_dynamics import run, swinging

    keys = {"t_end": 0.05, "output_dt": 1e-4, "method": "rk4", "dt": 2e-6}
    link = run(swinging("link", 3.5, **keys), kernels="loop")
    auto = run(swinging("auto", 3.5, **keys), kernels="loop")
    assert link["status"][0] & CONTACT_LOST and not auto["status"][0] & CONTACT_LOST
    switch = auto["first_separation_time"][0, 0]
    assert switch == link["contact_lost_time"][0]
    before = auto["time"] <= switch
    assert 100 < before.sum() < len(before)
    for name in ("q", "v", "joint_force", "contact_force", "energy", "constraint_error"):
        np.testing.assert_array_equal(auto[name][0, before], link[name][0, before], name)
    assert np.all(auto["contact_mode"][0, auto["time"] < switch, 0] == 0)


def test_constraint_pattern__rows_touch_their_bodies_and_the_envelope_is_tight():
    """The four-bar: rows O2 (0-1), A (2-3), B (4, clearance), O4 (5-6), the crank's driver
    (7); each row's coordinates, and the first row it shares one with."""
    model = scene_model("fourbar")
    cols, first = model.constraint_pattern()
    crank, coupler, rocker = [0, 1, 2], [3, 4, 5], [6, 7, 8]
    expected = [
        crank,
        crank,
        crank + coupler,
        crank + coupler,
        coupler + rocker,
        rocker,
        rocker,
        [2],
    ]
    for row, want in enumerate(expected):
        assert [c for c in cols[row] if c >= 0] == want, row
    np.testing.assert_array_equal(first, [0, 0, 0, 0, 2, 4, 4, 0])
    # S = B M⁻¹ Bᵀ is zero left of the envelope at any configuration
    q = np.random.default_rng(0).normal(size=model.ndof)
    B = dense.constraint_jacobian_formula(model, 0, q)
    S = B @ np.diag(1.0 / dense.mass_diagonal(model, 0)) @ B.T
    for i, f in enumerate(first):
        assert not S[i, :f].any()


def _simulate_section(**keys):
    from mcchain.scene.models import Simulate

    return Simulate(t_end=0.05, dt=1e-4, **keys)  # 500 steps


def test_choose_kernels__auto_takes_the_loop_only_for_short_runs_of_large_topologies():
    """``kernels = "auto"``: the loop kernels where the lanes would compile > 20 s (30 ms
    per coordinate and 0.46 ms per squared coordinate count) and the loop's extra time
    (0.27 µs per coordinate and instance-step) stays under a quarter of that compile;
    written values are kept."""
    from mcchain.solvers.kernel_choice import choose_kernels

    auto = _simulate_section()
    assert choose_kernels(_simulate_section(kernels="lanes"), 96, 1).kernels == "lanes"
    assert choose_kernels(_simulate_section(kernels="loop"), 6, 10**6).kernels == "loop"
    assert choose_kernels(auto, 178, 1).kernels == "lanes"  # 19.9 s of compile: in budget
    assert choose_kernels(auto, 179, 1).kernels == "loop"  # 20.1 s
    # 200 coordinates: 24.4 s of compile; 5.4e-5 s per instance-step; a quarter: 6.1 s
    assert choose_kernels(auto, 200, 225).kernels == "loop"  # 112,500 steps: 6.075 s
    assert choose_kernels(auto, 200, 226).kernels == "lanes"  # 113,000 steps: 6.102 s
    assert choose_kernels(_simulate_section(method="rk45"), 96, 1).kernels == "lanes"
    note = choose_kernels(auto, 200, 1).note()
    assert note is not None and note.startswith('simulate.kernels: "loop" (auto: ')
    assert 'kernels = "lanes"' in note and "200 coordinates" in note
    assert choose_kernels(auto, 200, 226).note() is None
    assert choose_kernels(_simulate_section(kernels="loop"), 200, 1).note() is None


def test_prepare_job__resolves_auto_once_for_the_whole_run(tmp_path):
    """A run resolves ``auto`` from its sample count (never per chunk): the job's scene, the
    stored settings and the note agree; ``simulate`` alone resolves it from its model."""
    from mcchain.runner.job import prepare_job

    n = 60  # 180 coordinates: the lanes would compile for about 20.3 s
    text = straight_chain_text([0.3] * n, [1.0] * n) + (
        '[simulate]\nt_end = 0.05\ndt = 1e-4\nmethod = "rk4"\n'
    )
    scene = write_scene(tmp_path, text, "chain60.toml")
    short = prepare_job(scene, samples=4)
    assert short.scene.simulate.kernels == "loop"
    assert short.settings["scene"]["simulate"]["kernels"] == "loop"
    assert len(short.notes) == 1 and "180 coordinates" in short.notes[0]
    long = prepare_job(scene, samples=2000)  # 1e6 instance-steps: 49 s more on the loop
    assert long.scene.simulate.kernels == "lanes" and long.notes == []
    assert long.settings["scene"]["simulate"]["kernels"] == "lanes"
