"""codegen: the fixed-step lanes' per-sample invariants of S = B M⁻¹ Bᵀ. An ideal revolute
joint to the ground has a 2×2 block of S whose determinant does not change with the state
(rows ``gdet``, computed once per sample: its second pivot divides for nothing); a clearance
row enters the solve multiplied by |d| (``ConstraintKinematics.scaled_rows``), its S_rr as
|d|² Σ 1/m (``SchurComplement.unit_rows``). The adaptive lanes keep the products written
out and the unit normal."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from test_simulate_methods import BAUMGARTE, T_ACCEL, accel_at_random_states

from mcchain.codegen.emitter import Emitter
from mcchain.codegen.generate import generate_source
from mcchain.codegen.kinematics import ConstraintKinematics
from mcchain.codegen.native import NativeModule
from mcchain.codegen.topology import Topology
from mcchain.contact import LAW_CODES
from mcchain.kernels.joints import clearance_gamma, clearance_gamma_scaled
from mcchain.model import JointKind
from mcchain.scene import compile_model, load_scene, load_scene_text
from mcchain.testing.dense import kkt_acceleration
from mcchain.testing.scenes import DOUBLE_PENDULUM, model_of, scene_model, straight_chain_text

CONFIGS = Path(__file__).resolve().parent.parent / "configs"


def _pendulum() -> Topology:
    model = model_of(straight_chain_text(**DOUBLE_PENDULUM, clearance={1: 5e-4}), nsample=2)
    return Topology.from_model(model)


def _fourbar() -> Topology:
    return Topology.from_model(compile_model(load_scene(CONFIGS / "fourbar-clearance.toml")))


def test_ground_revolutes__each_ideal_joint_to_the_ground_with_its_body_and_point():
    topo = _pendulum()  # joint 0: ground to body 0 (ideal); joint 1: body 0 to 1 (clearance)
    assert topo.ground_revolutes == (0,)
    assert Emitter(topo).ground_revolutes() == {frozenset((0, 1)): (0, 0, "sbx0", "sby0")}
    four = _fourbar()
    pairs = Emitter(four).ground_revolutes()
    assert len(pairs) == 2  # the crank and the rocker on the ground
    assert sorted(k for k, *_ in pairs.values()) == list(four.ground_revolutes)
    for rows, (k, body, sx, sy) in pairs.items():
        a, b = four.joint_a[k], four.joint_b[k]
        assert -1 in (a, b) and body == (b if a == -1 else a)
        assert rows == frozenset((four.joint_row[k], four.joint_row[k] + 1))
        assert sx[:3] in ("sax", "sbx") and sy == sx[:2] + "y" + sx[3:]


def test_ground_determinant__is_the_blocks_determinant_at_every_angle():
    """The generated setup lines of rows gdet, evaluated on random parameters, against
    det(1/m I + 1/J w wᵀ) (w the joint's point turned by θ and a right angle) at random θ,
    and 1/det."""
    topo = _pendulum()
    text = generate_source(topo, "rk4", lmax=4)
    lines = re.findall(r"^\s*(W\[\d+ \+ l\] = .*(?:\* \(W|1\.0 / W).*)$", text, flags=re.M)
    det_line, inverse_line = lines[:2]
    slots = topo.slots()
    rng = np.random.default_rng(3)
    for _ in range(20):
        W = np.zeros(4 * 400)
        im, ij = 1.0 / rng.uniform(0.1, 5.0), 1.0 / rng.uniform(1e-3, 1.0)
        s = rng.uniform(-0.5, 0.5, 2)
        for name, value in (("im0", im), ("iJ0", ij), ("sbx0", s[0]), ("sby0", s[1])):
            W[slots[name] * 4] = value
        exec(det_line + "\n" + inverse_line, {"W": W, "l": 0})
        det_row = int(re.match(r"\s*W\[(\d+)", det_line).group(1))
        inv_row = int(re.match(r"\s*W\[(\d+)", inverse_line).group(1))
        for theta in rng.uniform(-20.0, 20.0, 5):
            c, sn = np.cos(theta), np.sin(theta)
            p = np.array([c * s[0] - sn * s[1], sn * s[0] + c * s[1]])
            w = np.array([-p[1], p[0]])
            block = im * np.eye(2) + ij * np.outer(w, w)
            assert np.isclose(W[det_row], np.linalg.det(block), rtol=1e-13, atol=0.0)
        assert W[inv_row] == 1.0 / W[det_row]


def _stage(text: str) -> str:
    """The stage's line of S_rr of the clearance row (the pendulum's row 2)."""
    return next(line for line in text.splitlines() if re.match(r"\s*S2_2\w* = ", line))


def test_fixed_step_lanes__use_the_invariants_the_adaptive_ones_do_not():
    topo = _pendulum()
    rk4, rk45 = generate_source(topo, "rk4", lmax=4), generate_source(topo, "rk45", lmax=4)
    assert "gdet" in rk4 and "gdet" not in rk45
    # pivot 1 (the ground joint's y row): N1 read from gdet, 1/d1 a product, no division
    assert re.search(r"N1\w* = W\[\d+ \+ l\]\n", rk4)
    assert re.search(r"Di1\w* = Dp1_0\w* \* W\[\d+ \+ l\] if", rk4)
    assert re.search(r"Di1\w* = okp1\w* / \(okp1\w* \* D1", rk45)  # sequential, as before
    # S_rr of the clearance row: |d|² (1/m₀ + 1/m₁), not d_x² /m + d_y² /m
    assert re.search(r"= \(rr1\w* \* \(p_im0\w* \+ p_im1\w*\) \+", _stage(rk4))
    assert "Wt2_0" not in _stage(rk4)
    assert "Wt2_0" in _stage(rk45) and "Wt2_3" in _stage(rk45)
    # the clearance row scaled by |d| in the fixed-step lanes only: no 1/|d| before the solve
    assert "ex1" not in _stage(rk4) and "ex1" in _stage(rk45)


def test_clearance_gamma_scaled__is_the_distance_times_gamma():
    """|d| γ in the cross-product form against |d| times γ written with e = d/|d|, to the
    rounding of the terms they sum, over separations from 1e-6 m to 1 m."""
    rng = np.random.default_rng(11)
    for _ in range(2000):
        d = rng.normal(size=2) * 10.0 ** rng.uniform(-6, 0)
        rate, g = rng.normal(size=2) * 10.0 ** rng.uniform(-3, 1), rng.normal(size=2) * 100
        rho = float(np.hypot(*d))
        e = d / rho
        reference = rho * clearance_gamma(*e, *g, *rate, float(e @ rate), 1.0 / rho)
        scaled = clearance_gamma_scaled(*d, *g, *rate, 1.0 / (rho * rho))
        scale = rho * (float(np.abs(g).sum()) + float(rate @ rate) / rho)
        assert abs(scaled - reference) <= 1e-14 * scale


@pytest.mark.parametrize("name", ["clearance_bar", "fourbar", "double_pendulum", "slider_crank"])
def test_scaled_clearance_rows__the_dense_solves_accelerations_and_multipliers(name, monkeypatch):
    """The acceleration with every clearance row scaled by |d| (the fixed-step lanes' form),
    written into the accel kernel, at random states off the constraints (Baumgarte terms
    on): q̈ and λ (multiplied back by |d|) of the dense KKT solve, as the unscaled text
    gives them (test_simulate_methods)."""
    model = scene_model(name)
    assert JointKind.CLEARANCE in set(model.joint_kind.tolist()) or name == "slider_crank"
    topo = Topology.from_model(model)
    # on, and kept on: the generator sets the flag per variant (off for accel)
    always = property(lambda self: True, lambda self, value: None)
    monkeypatch.setattr(ConstraintKinematics, "scaled_rows", always)
    source = generate_source(topo, "accel")
    # the scaled form is the one written: |d|² named for each clearance row (none without)
    assert bool(re.search(r"^\s*rr\d+\w* = ", source, re.M)) == (name != "slider_crank")
    module = NativeModule(source, f"scaled_rows_{name}")
    _, Q, V, qdd, lam, _, sing = accel_at_random_states(module, model, topo, n=6, seed=5)
    for j in range(Q.shape[1]):
        ref_qdd, ref_lam = kkt_acceleration(model, 0, Q[:, j], V[:, j], T_ACCEL, BAUMGARTE)
        np.testing.assert_allclose(qdd[:, j], ref_qdd, rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(lam[:, j], ref_lam, rtol=1e-10, atol=1e-10)
        assert sing[j] == 0.0


def test_contact_law__the_scenes_law_is_a_literal_of_the_text():
    """[joint.contact] law is not sampled: the lanes' text evaluates χ(e) of the scene's law
    alone (restitution_factor's other branches, three of them divisions, are not in it), and
    each law has a text of its own."""
    written = (CONFIGS / "fourbar-clearance.toml").read_text()
    assert 'law = "lankarani-nikravesh"' in written
    texts = {}
    for law in LAW_CODES:
        scene = load_scene_text(written.replace('"lankarani-nikravesh"', f'"{law}"'))
        topo = Topology.from_model(compile_model(scene))
        assert topo.law(2) == LAW_CODES[law]  # joint B
        texts[law] = generate_source(topo, "rk45", lmax=4)
        assert not re.search(r"p_lw\d+(__\d+)? ==", texts[law]), law  # no branch on the law
    assert len(set(texts.values())) == len(LAW_CODES)


def test_contact_friction__terms_only_where_some_sample_has_friction():
    """A contact joint with μ = 0 in every sample has no friction terms in the lanes' text
    (at μ = 0 they are exact zeros); μ swept over the samples brings them back."""
    written = (CONFIGS / "fourbar-clearance.toml").read_text()
    frictionless = Topology.from_model(compile_model(load_scene_text(written)))
    assert frictionless.joint_friction == (0, 0, 0, 0) and not frictionless.friction(2)
    text = generate_source(frictionless, "rk45", lmax=4)
    assert not re.search(r"\b(slip|ftn|ft)2(__\d+)? = ", text)
    swept = written.replace(
        "[sample.vary]\n", '[sample.vary]\n"joint.B.contact.friction" = { uniform = [0.0, 0.1] }\n'
    )
    model = compile_model(load_scene_text(swept))
    assert model.joint_contact_friction.shape == (model.nsample, 4)
    rubbing = Topology.from_model(model)
    assert rubbing.joint_friction == (0, 0, 1, 0) and rubbing.friction(2)
    assert re.search(r"\bslip2(__\d+)? = ", generate_source(rubbing, "rk45", lmax=4))
