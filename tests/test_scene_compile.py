"""Scene -> Model: topology, defaults, where sampled paths land, broadcasting, speed."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from mcchain.errors import SceneError
from mcchain.model import GROUND, JOINT_CLEARANCE, JOINT_IDEAL, PER_SAMPLE_FIELDS, constraint_rows
from mcchain.scene import compile_model, load_scene_text
from mcchain.testing.factory import (
    chain_scene_dict,
    chain_scene_text,
    clearance_bar_text,
    constraint_residual,
    rotation,
    toml_text,
)

CONSISTENT_TOL = 1e-14
"""Constraint residual of the factory's initial positions, m (rounding of a few bars)."""


# -- topology and defaults -----------------------------------------------------------------
def test_compile_model__topology_and_rows() -> None:
    text = chain_scene_text(3, [1], seed=1, springs=1, forces=2, driver=True)
    model = compile_model(load_scene_text(text))
    assert model.body_names == ("b0", "b1", "b2")
    assert model.joint_names == ("J0", "J1", "J2")
    np.testing.assert_array_equal(model.joint_body_a, [GROUND, 0, 1])
    np.testing.assert_array_equal(model.joint_body_b, [0, 1, 2])
    np.testing.assert_array_equal(model.joint_kind, [JOINT_IDEAL, JOINT_CLEARANCE, JOINT_IDEAL])
    np.testing.assert_array_equal(model.joint_row, [0, 2, 3])
    np.testing.assert_array_equal(model.driver_row, [5])
    np.testing.assert_array_equal(model.driver_body, [0])
    assert model.ncon == 6 and model.nmode == 3
    assert model.spring_body_a[0] == GROUND
    for name in ("joint_body_a", "joint_kind", "joint_row", "driver_row", "force_body"):
        assert getattr(model, name).dtype == np.int64
    assert model.nsample == 1 and model.parameters.shape == (1, 0) and model.param_paths == ()
    assert model.meta == {
        "scene_name": "chain",
        "seed": 0,
        "design": None,
        "nsample": 1,
        "written": {
            "position": (True, True, True),
            "angle": (True, True, True),
            "velocity": (False, False, False),
            "angular_velocity": (False, False, False),
        },
    }


def test_compile_model__defaults_in_arrays() -> None:
    text = (
        '[[body]]\nname = "a"\nmass = 1\ninertia = 0.5\nangle = 0.25\n'
        '[[joint]]\nbodies = ["ground", "a"]\npoints = [[0, 0], [0, 0]]\nclearance = 1e-4\n'
        '[[driver]]\nbody = "a"\nomega = 3\n'
        '[[force]]\nbody = "a"\ntorque = 2\n'
        '[[spring]]\nbodies = ["ground", "a"]\npoints = [[3, 4], [0, 0]]\nstiffness = 5\n'
    )
    model = compile_model(load_scene_text(text))
    np.testing.assert_array_equal(model.gravity, [[0.0, -9.81]])
    assert np.isnan(model.joint_eccentricity[0, 0])
    assert model.joint_kind[0] == JOINT_CLEARANCE
    assert model.driver_angle0[0, 0] == 0.25
    np.testing.assert_array_equal(model.force_value, [[[0.0, 0.0]]])
    np.testing.assert_array_equal(model.force_point, [[[0.0, 0.0]]])
    assert model.force_torque[0, 0] == 2.0
    assert model.spring_rest_length[0, 0] == 5.0  # |(3, 4) - (0, 0)|: unstressed at t = 0
    assert model.spring_damping[0, 0] == 0.0
    np.testing.assert_array_equal(model.v0, [[0.0, 0.0, 0.0]])
    np.testing.assert_array_equal(model.q0, [[0.0, 0.0, 0.25]])


def test_compile_model__no_sample_with_nsample_override() -> None:
    model = compile_model(load_scene_text(clearance_bar_text()), nsample=5, seed=3)
    assert model.nsample == 5 and model.parameters.shape == (5, 0)
    for name in PER_SAMPLE_FIELDS:
        assert getattr(model, name).shape[0] == 1, name
    assert model.meta["seed"] == 3


@pytest.mark.parametrize(
    ("nsample", "seed", "match"),
    [
        (0, None, r"^nsample: must be >= 1, got 0$"),
        (2.5, None, r"^nsample: expected an integer"),
        (1, -1, r"^seed: must be in \[0, "),
        (1, 2**64, r"^seed: must be in \[0, "),
    ],
)
def test_compile_model__bad_nsample_or_seed(nsample, seed, match: str) -> None:
    with pytest.raises(SceneError, match=match):
        compile_model(load_scene_text(clearance_bar_text()), nsample=nsample, seed=seed)


# -- sampled paths -------------------------------------------------------------------------
PATHS = {
    "scene.gravity[1]": ("gravity", (1,)),
    "body.b1.mass": ("body_mass", (1,)),
    "body.b0.inertia": ("body_inertia", (0,)),
    "body.b1.position[0]": ("q0", (3,)),
    "body.b1.position[1]": ("q0", (4,)),
    "body.b2.angle": ("q0", (8,)),
    "body.b0.velocity[1]": ("v0", (1,)),
    "body.b2.angular_velocity": ("v0", (8,)),
    "joint.J1.points[0][0]": ("joint_point_a", (1, 0)),
    "joint.J2.points[1][1]": ("joint_point_b", (2, 1)),
    "joint.J1.clearance": ("joint_clearance", (1,)),
    "joint.J1.eccentricity": ("joint_eccentricity", (1,)),
    "driver.b0.omega": ("driver_omega", (0,)),
    "driver.b0.angle0": ("driver_angle0", (0,)),
    "force.F0.point[1]": ("force_point", (0, 1)),
    "force.F1.value[0]": ("force_value", (1, 0)),
    "force.F1.torque": ("force_torque", (1,)),
    "spring.S0.points[0][1]": ("spring_point_a", (0, 1)),
    "spring.S0.points[1][0]": ("spring_point_b", (0, 0)),
    "spring.S0.stiffness": ("spring_stiffness", (0,)),
    "spring.S0.rest_length": ("spring_rest_length", (0,)),
    "spring.S0.damping": ("spring_damping", (0,)),
}


@pytest.mark.parametrize("path", list(PATHS))
def test_compile_model__sampled_path_lands_in_its_slot(path: str) -> None:
    doc = chain_scene_dict(3, [1], seed=4, springs=1, forces=2, driver=True)
    doc["spring"][0]["rest_length"] = 0.3  # a default rest length would follow positions
    doc["driver"][0]["angle0"] = -1.5  # a default angle0 would follow the body's angle
    base = compile_model(load_scene_text(toml_text(doc)))
    low, high = (5e-4, 7.5e-4) if path.endswith("clearance") else (0.5, 0.75)  # m for clearance
    doc["sample"] = {"count": 16, "seed": 4, "vary": {path: {"uniform": [low, high]}}}
    model = compile_model(load_scene_text(toml_text(doc)))
    name, idx = PATHS[path]
    arr = getattr(model, name)
    assert arr.shape == (16, *getattr(base, name).shape[1:])
    np.testing.assert_array_equal(arr[(slice(None), *idx)], model.parameters[:, 0])
    # every other slot of the varied array keeps its scene value
    mask = np.ones(arr.shape[1:], dtype=bool)
    mask[idx] = False
    expected = getattr(base, name)[0][mask]
    np.testing.assert_array_equal(arr[:, mask], np.broadcast_to(expected, (16, expected.size)))
    for other in PER_SAMPLE_FIELDS - {name}:
        assert getattr(model, other).shape[0] == 1, other
        np.testing.assert_array_equal(getattr(model, other), getattr(base, other), err_msg=other)
    assert model.param_paths == (path,)


def test_compile_model__sampled_clearance_makes_a_clearance_joint() -> None:
    vary = {"joint.J0.clearance": {"uniform": [1e-4, 2e-4]}}
    model = compile_model(load_scene_text(chain_scene_text(2, [], seed=0, sample=4, vary=vary)))
    np.testing.assert_array_equal(model.joint_kind, [JOINT_CLEARANCE, JOINT_IDEAL])
    np.testing.assert_array_equal(model.joint_row, [0, 1])
    assert np.isnan(model.joint_eccentricity).all()


def test_compile_model__driver_angle0_follows_sampled_body_angle() -> None:
    vary = {"body.b0.angle": {"uniform": [-2.0, -1.0]}}
    text = chain_scene_text(2, [], seed=0, driver=True, sample=8, vary=vary)
    model = compile_model(load_scene_text(text))
    np.testing.assert_array_equal(model.driver_angle0[:, 0], model.q0[:, 2])
    # an explicit angle0 does not follow
    doc = chain_scene_dict(2, [], seed=0, driver=True, sample=8, vary=vary)
    doc["driver"][0]["angle0"] = 0.5
    model = compile_model(load_scene_text(toml_text(doc)))
    assert model.driver_angle0.shape == (1, 1) and model.driver_angle0[0, 0] == 0.5


def test_compile_model__default_rest_length_follows_sampled_positions() -> None:
    doc = chain_scene_dict(
        1, [], seed=0, springs=1, sample=6, vary={"body.b0.angle": {"uniform": [-2.0, -1.0]}}
    )
    doc["spring"][0].pop("rest_length", None)
    anchor = np.array(doc["spring"][0]["points"][0])
    local = np.array(doc["spring"][0]["points"][1])
    model = compile_model(load_scene_text(toml_text(doc)))
    q = model.q0
    tips = np.array([q[i, :2] + rotation(q[i, 2]) @ local for i in range(6)])
    np.testing.assert_allclose(
        model.spring_rest_length[:, 0], np.hypot(*(tips - anchor).T), rtol=1e-15
    )
    # unrelated variation keeps the default rest length a single row
    doc["sample"]["vary"] = {"body.b0.mass": {"uniform": [1.0, 2.0]}}
    assert compile_model(load_scene_text(toml_text(doc))).spring_rest_length.shape == (1, 1)


def test_compile_model__sampled_value_outside_domain_names_path_and_sample() -> None:
    vary = {"body.b0.mass": {"normal": [0.01, 1.0]}}
    scene = load_scene_text(chain_scene_text(1, [], seed=0, sample=100, vary=vary))
    with pytest.raises(
        SceneError,
        match=r'^sample\.vary\."body\.b0\.mass": sampled value -?\d.* '
        r"at sample \d+: mass must be > 0\.0",
    ):
        compile_model(scene)


@pytest.mark.parametrize("design", ["random", "sobol"])
def test_compile_model__sample_rows_independent_of_count(design: str) -> None:
    text = chain_scene_text(3, [0, 2], seed=7, sample=1000, design=design)
    scene = load_scene_text(text)
    small = compile_model(scene, nsample=10)
    big = compile_model(scene, nsample=1000)
    np.testing.assert_array_equal(small.parameters, big.parameters[:10])
    np.testing.assert_array_equal(small.body_mass, big.body_mass[:10])
    chunk = big.select(500, 600)
    np.testing.assert_array_equal(chunk.joint_clearance, big.joint_clearance[500:600])


def test_compile_model__saltelli_rows_independent_of_count_and_count_checked() -> None:
    vary = {
        "body.b1.mass": {"uniform": [0.5, 1.5]},
        "joint.J0.clearance": {"uniform": [1e-4, 1e-3]},
    }
    text = chain_scene_text(2, [0], seed=7, sample=400, design="saltelli", vary=vary)
    scene = load_scene_text(text)
    big = compile_model(scene)
    assert big.meta["design"] == "saltelli" and big.parameters.shape == (400, 2)
    small = compile_model(scene, nsample=12)
    np.testing.assert_array_equal(small.parameters, big.parameters[:12])
    np.testing.assert_array_equal(small.joint_clearance, big.joint_clearance[:12])
    groups = big.parameters.reshape(100, 4, 2)  # A, AB_1, AB_2, B per base point
    np.testing.assert_array_equal(groups[:, 1, 1], groups[:, 0, 1])
    np.testing.assert_array_equal(groups[:, 1, 0], groups[:, 3, 0])
    np.testing.assert_array_equal(big.body_mass[:, 1], big.parameters[:, 0])
    with pytest.raises(
        SceneError,
        match=r"^nsample: must be a multiple of 4 \(= number of varied paths \+ 2\) for design "
        r'"saltelli", got 1001$',
    ):
        compile_model(scene, nsample=1001)
    scene.sample.count = 10  # type: ignore[union-attr]
    with pytest.raises(SceneError, match=r"^sample\.count: must be a multiple of 4 .* got 10$"):
        compile_model(scene)


def test_compile_model__reproducible_from_seed() -> None:
    scene = load_scene_text(chain_scene_text(2, [1], seed=7, sample=50, design="lhs"))
    a, b = compile_model(scene), compile_model(scene)
    np.testing.assert_array_equal(a.parameters, b.parameters)
    c = compile_model(scene, seed=8)
    assert not np.array_equal(a.parameters, c.parameters)
    assert (a.meta["seed"], c.meta["seed"], a.meta["design"]) == (7, 8, "lhs")


# -- property test over random factory chains -----------------------------------------------
VARIABLE = [
    ("body.b{k}.mass", {"uniform": [0.5, 1.5]}),
    ("body.b{k}.angle", {"normal": [-1.5, 0.1]}),
    ("body.b{k}.position[1]", {"uniform": [-1.0, 0.0]}),
    ("joint.J{k}.clearance", {"uniform": [1e-4, 1e-3]}),
    ("joint.J{k}.points[1][0]", {"truncnormal": [-0.1, 0.01, -0.2, 0.0]}),
    ("scene.gravity[1]", {"choice": [-9.81, -9.80]}),
]


@st.composite
def chains(draw: st.DrawFn) -> tuple[str, int | None, set[str]]:
    nbody = draw(st.integers(1, 5))
    clearance = draw(st.sets(st.integers(0, nbody - 1)))
    count = draw(st.one_of(st.none(), st.integers(1, 40)))
    vary = {}
    if count is not None:
        for template, dist in draw(st.lists(st.sampled_from(VARIABLE), max_size=4)):
            k = draw(st.integers(0, nbody - 1))
            vary[template.format(k=k)] = dist
    text = chain_scene_text(
        nbody,
        clearance,
        seed=draw(st.integers(0, 2**32)),
        springs=draw(st.integers(0, 2)),
        forces=draw(st.integers(0, 2)),
        driver=draw(st.booleans()),
        sample=count,
        design=draw(st.sampled_from(["random", "sobol", "lhs"])),
        vary=vary,
    )
    return text, count, set(vary)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(chains())
def test_compile_model__random_chains_shapes_and_broadcasting(case) -> None:
    text, count, varied = case
    scene = load_scene_text(text)
    model = compile_model(scene)
    n = count or 1
    nb, nj, nd, nf, ns = (model.nbody, model.njoint, model.ndriver, model.nforce, model.nspring)
    assert model.nsample == n
    assert model.parameters.shape == (n, len(varied))
    assert model.param_paths == tuple(scene.param_paths)
    trailing = {
        "gravity": (2,),
        "body_mass": (nb,),
        "body_inertia": (nb,),
        "joint_point_a": (nj, 2),
        "joint_point_b": (nj, 2),
        "joint_clearance": (nj,),
        "joint_eccentricity": (nj,),
        "joint_axis": (nj, 2),
        "joint_relative_angle": (nj,),
        "joint_contact_stiffness": (nj,),
        "joint_contact_exponent": (nj,),
        "joint_contact_restitution": (nj,),
        "joint_contact_friction": (nj,),
        "joint_contact_radius": (nj,),
        "driver_angle0": (nd,),
        "driver_omega": (nd,),
        "driver_amplitude": (nd,),
        "driver_frequency": (nd,),
        "driver_phase": (nd,),
        "driver_displacement0": (nd,),
        "driver_speed": (nd,),
        "force_point": (nf, 2),
        "force_value": (nf, 2),
        "force_torque": (nf,),
        "force_frequency": (nf,),
        "force_phase": (nf,),
        "spring_point_a": (ns, 2),
        "spring_point_b": (ns, 2),
        "spring_stiffness": (ns,),
        "spring_rest_length": (ns,),
        "spring_damping": (ns,),
        "q0": (3 * nb,),
        "v0": (3 * nb,),
    }
    assert set(trailing) == set(PER_SAMPLE_FIELDS)
    for name, shape in trailing.items():
        arr = getattr(model, name)
        assert arr.dtype == np.float64 and arr.flags.c_contiguous, name
        assert arr.shape[1:] == shape, name
        assert arr.shape[0] in (1, n), name
        unset = (
            "joint_eccentricity",
            "joint_contact_stiffness",
            "joint_axis",
            "joint_relative_angle",
            "driver_displacement0",
        )
        if name not in unset:  # NaN: unset
            assert np.all(np.isfinite(arr)), name
    joint_row, driver_row = constraint_rows(model.joint_kind, nd)
    np.testing.assert_array_equal(model.joint_row, joint_row)
    np.testing.assert_array_equal(model.driver_row, driver_row)
    for k, joint in enumerate(scene.joint):
        is_clearance = joint.clearance > 0 or f"joint.{joint.name}.clearance" in varied
        assert model.joint_kind[k] == (JOINT_CLEARANCE if is_clearance else JOINT_IDEAL)
        ecc = model.joint_eccentricity[:, k]
        given_ecc = joint.eccentricity is not None or f"joint.{joint.name}.eccentricity" in varied
        assert np.isnan(ecc).all() != given_ecc
    if n > 1 and varied:
        assert any(getattr(model, f).shape[0] == n for f in PER_SAMPLE_FIELDS)
    kernel = model.kernel_arrays()
    assert all(isinstance(a, np.ndarray) for a in kernel)
    if not varied:
        assert constraint_residual(model) < CONSISTENT_TOL
    chunk = model.select(0, max(n // 2, 1))
    assert chunk.parameters.shape[0] == max(n // 2, 1)


def test_factory__bars_hang_consistently() -> None:
    for k in range(1, 6):
        text = chain_scene_text(k, range(k), seed=k, driver=True)
        assert constraint_residual(compile_model(load_scene_text(text))) < CONSISTENT_TOL
    assert math.isfinite(constraint_residual(compile_model(load_scene_text(clearance_bar_text()))))
