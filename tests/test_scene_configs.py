"""The shipped configs/*.toml: they load, compile, round-trip, and start consistent."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from mcchain.model import JOINT_CLEARANCE, JOINT_IDEAL
from mcchain.scene import compile_model, load_scene, load_scene_text
from mcchain.solvers.statics import initial_state_warnings, written_state
from mcchain.testing.closed_forms import G, bar_pulsation, clearance_bar_pulsations
from mcchain.testing.factory import constraint_residual, toml_text

CONFIGS = sorted((Path(__file__).parent.parent / "configs").glob("*.toml"))
NAMES = [p.stem for p in CONFIGS]

CONSISTENT_TOL = 1e-15
"""Constraint residual of a config's written positions, m: exact up to rounding."""
VELOCITY_TOL = 1e-14
"""Residual of the velocity constraints B v = -Φ_t of the driven four-bar, m/s."""

EXPECTED = {
    "paper-bar",
    "clearance-bar",
    "clearance-bar-tip-load",
    "clearance-sweep",
    "clearance-sweep-sobol",
    "double-pendulum",
    "double-pendulum-clearance",
    "fourbar-clearance",
    "fourbar-clearance-statics",
}


def test_configs__all_present() -> None:
    assert EXPECTED <= set(NAMES)


def _nominal(path: Path):
    scene = load_scene(path)
    scene.sample = None  # the written (nominal) instance
    return scene, compile_model(scene)


@pytest.mark.parametrize("path", CONFIGS, ids=NAMES)
def test_config__loads_compiles_and_names_itself(path: Path) -> None:
    scene = load_scene(path)
    assert scene.name == path.stem
    assert scene.text == path.read_text()
    model = compile_model(scene, nsample=min(scene.sample.count, 64) if scene.sample else None)
    assert model.nsample == (min(scene.sample.count, 64) if scene.sample else 1)
    if scene.driver:  # a driven mechanism runs, or has its modes followed along the turn
        assert scene.simulate is not None or (scene.modes and scene.modes.along)
    else:
        assert scene.equilibrium is not None and scene.modes is not None


@pytest.mark.parametrize("path", CONFIGS, ids=NAMES)
def test_config__round_trips_through_toml(path: Path) -> None:
    scene = load_scene(path)
    dumped = scene.model_dump(exclude_none=True)
    again = load_scene_text(toml_text(dumped))
    assert again.model_dump(exclude_none=True) == dumped
    a = compile_model(scene, nsample=8)
    b = compile_model(again, nsample=8)
    for name in a.kernel_arrays()._fields:
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    np.testing.assert_array_equal(a.parameters, b.parameters)


@pytest.mark.parametrize("path", CONFIGS, ids=NAMES)
def test_config__initial_positions_satisfy_the_joints(path: Path) -> None:
    """Written positions satisfy every joint to rounding; a config written with its
    dimensions only (no position) assembles with nothing to warn about."""
    scene, model = _nominal(path)
    if all(body.position is not None for body in scene.body):
        assert constraint_residual(model) < CONSISTENT_TOL
    else:
        written, assembled = written_state(scene)
        assert assembled.status[0] == 0
        assert initial_state_warnings(written, assembled) == []


def test_config__paper_bars_match_design_geometry() -> None:
    _, bar = _nominal(CONFIGS[NAMES.index("paper-bar")])
    assert bar.joint_kind.tolist() == [JOINT_IDEAL]
    m, J = bar.body_mass[0, 0], bar.body_inertia[0, 0]
    assert (m, J) == (2.0, 2.0 * 1.0**2 / 12)
    assert bar_pulsation(m, J, 0.5) ** 2 == pytest.approx(14.715)
    _, cbar = _nominal(CONFIGS[NAMES.index("clearance-bar")])
    assert cbar.joint_kind.tolist() == [JOINT_CLEARANCE]
    assert cbar.joint_clearance[0, 0] == 1e-3
    assert cbar.joint_eccentricity[0, 0] == -math.pi / 2
    assert clearance_bar_pulsations(m, J, 0.5, G, 1e-3)[0] < bar_pulsation(m, J, 0.5)
    _, tmodel = _nominal(CONFIGS[NAMES.index("clearance-bar-tip-load")])
    np.testing.assert_array_equal(tmodel.force_value, [[[5.0, 0.0]]])
    np.testing.assert_array_equal(tmodel.force_point, [[[0.5, 0.0]]])


def test_config__clearance_sweep_settings() -> None:
    scene = load_scene(CONFIGS[NAMES.index("clearance-sweep")])
    assert scene.sample is not None
    assert (scene.sample.count, scene.sample.seed, scene.sample.design) == (10000, 7, "sobol")
    assert scene.param_paths == ["joint.O.clearance", "body.bar.mass"]
    assert scene.sample.vary["joint.O.clearance"].uniform == [1e-4, 1e-3]
    assert scene.sample.vary["body.bar.mass"].normal == [2.0, 0.02]
    model = compile_model(scene)
    assert model.parameters.shape == (10000, 2)
    assert model.joint_clearance.shape == (10000, 1) and model.body_mass.shape == (10000, 1)
    assert model.body_inertia.shape == (1, 1)


def test_config__clearance_sweep_sobol_is_the_sweep_in_saltellis_layout() -> None:
    scene = load_scene(CONFIGS[NAMES.index("clearance-sweep-sobol")])
    sweep = load_scene(CONFIGS[NAMES.index("clearance-sweep")])
    assert scene.sample is not None and sweep.sample is not None
    assert (scene.sample.count, scene.sample.seed, scene.sample.design) == (4096, 7, "saltelli")
    assert scene.sample.vary == sweep.sample.vary
    assert scene.equilibrium is not None and scene.modes is not None
    assert scene.body == sweep.body and scene.joint == sweep.joint
    model = compile_model(scene)
    assert model.meta["design"] == "saltelli" and model.parameters.shape == (4096, 2)
    groups = model.parameters.reshape(1024, 4, 2)  # A, AB_1, AB_2, B per base point
    np.testing.assert_array_equal(groups[:, 1], np.column_stack([groups[:, 3, 0], groups[:, 0, 1]]))
    np.testing.assert_array_equal(groups[:, 2], np.column_stack([groups[:, 0, 0], groups[:, 3, 1]]))


def test_config__double_pendulums() -> None:
    for name, kinds in (
        ("double-pendulum", [JOINT_IDEAL, JOINT_IDEAL]),
        ("double-pendulum-clearance", [JOINT_IDEAL, JOINT_CLEARANCE]),
    ):
        scene, model = _nominal(CONFIGS[NAMES.index(name)])
        assert model.joint_kind.tolist() == kinds
        np.testing.assert_array_equal(model.body_mass, [[1.5, 1.0]])
        np.testing.assert_allclose(model.body_inertia, [[1.5 * 0.36 / 12, 1.0 * 0.16 / 12]])
        sim = scene.simulate
        assert sim is not None
        assert (sim.t_end, sim.dt, sim.output_dt, sim.method) == (1.0, 1e-5, 1e-3, "rk4")


def test_config__fourbar_is_a_consistent_driven_crank_rocker() -> None:
    scene, model = _nominal(CONFIGS[NAMES.index("fourbar-clearance")])
    assert model.driver_names == ("crank",) and model.driver_omega[0, 0] == 20.0
    assert model.driver_angle0[0, 0] == model.q0[0, 2]
    assert model.joint_kind.tolist() == [JOINT_IDEAL, JOINT_IDEAL, JOINT_CLEARANCE, JOINT_IDEAL]
    assert scene.simulate is not None
    assert scene.simulate.t_end == pytest.approx(2 * 2 * math.pi / 20.0)
    # link lengths from the joint points: ground 0.3, crank 0.1, coupler 0.3, rocker 0.25
    pa, pb = model.joint_point_a[0], model.joint_point_b[0]
    assert pa[3, 0] - pa[0, 0] == pytest.approx(0.3)
    assert pa[1, 0] - pb[0, 0] == pytest.approx(0.1)
    assert pa[2, 0] - pb[1, 0] == pytest.approx(0.3)
    assert pb[2, 0] - pb[3, 0] == pytest.approx(0.25)
    # velocities: ideal joints and the journal have d' = 0, the crank turns at ω
    q, v = model.q0[0], model.v0[0]
    omega = np.array([[0.0, -1.0], [1.0, 0.0]])
    res = []
    for k in range(model.njoint):
        dv = np.zeros(2)
        for body, local, sign in (
            (model.joint_body_a[k], pa[k], -1.0),
            (model.joint_body_b[k], pb[k], 1.0),
        ):
            if body >= 0:
                c, s = math.cos(q[3 * body + 2]), math.sin(q[3 * body + 2])
                rot = np.array([[c, -s], [s, c]])
                dv += sign * (v[3 * body : 3 * body + 2] + omega @ rot @ local * v[3 * body + 2])
        res.extend(np.abs(dv))
    assert max(res) < VELOCITY_TOL
    assert v[2] == 20.0
    full = load_scene(CONFIGS[NAMES.index("fourbar-clearance")])
    assert full.param_paths == ["joint.B.clearance"]


def test_config__fourbar_statics_has_spring_and_no_driver() -> None:
    scene, model = _nominal(CONFIGS[NAMES.index("fourbar-clearance-statics")])
    assert model.ndriver == 0 and model.nspring == 1
    assert model.joint_kind.tolist() == [JOINT_IDEAL, JOINT_IDEAL, JOINT_CLEARANCE, JOINT_IDEAL]
    assert model.nmode == 2
    assert scene.equilibrium is not None and scene.modes is not None
