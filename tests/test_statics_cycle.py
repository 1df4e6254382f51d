"""Modes along a cycle (``[modes] along``): the driven four-bar frozen at configurations over
one crank turn, each against a dense reference of the same (q, λ), and in a run."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from mcchain.scene import compile_model, load_scene_text
from mcchain.solvers import solve_chunk
from mcchain.solvers.statics import assemble, solve_modes_along
from mcchain.testing import dense
from mcchain.testing.scenes import fourbar_text

POINTS = 12


@pytest.fixture(scope="module")
def cycle():
    sample = '[sample]\ncount = 3\nseed = 1\n[sample.vary]\n"joint.B.clearance" = '
    sample += "{ uniform = [5e-5, 2e-4] }\n"
    model = compile_model(load_scene_text(fourbar_text() + sample))
    start = assemble(model)
    return model, solve_modes_along(model, 0, POINTS, start.q, start.v)


@pytest.mark.parametrize("j", [0, 4, 9])
def test_cycle__modes_equal_a_dense_eigen_solve_of_the_frozen_configuration(cycle, j):
    model, result = cycle
    for s in range(model.nsample):
        angle0 = model.driver_angle0[s % model.driver_angle0.shape[0]].copy()
        frozen = replace(model, driver_angle0=(angle0 + result.phase[j])[None, :])
        q, v, lam = result.q[s, j], result.v[s, j], result.lam[s, j]
        # the configuration closes every joint with the crank at its angle, contact holds
        assert np.abs(dense.constraints(frozen, s, q)).max() <= 1e-13
        _, reference_lam = dense.kkt_acceleration(frozen, s, q, v, 0.0)
        np.testing.assert_allclose(lam, reference_lam, rtol=1e-10, atol=1e-10)
        assert lam[int(model.joint_row[2])] > 0.0
        expected = dense.modes(frozen, s, q, lam)
        np.testing.assert_allclose(result.omega[s, j], expected, rtol=1e-10)


def test_cycle__phases_turn_the_crank_and_keep_the_branch(cycle):
    _, result = cycle
    np.testing.assert_allclose(result.phase, 2 * np.pi * np.arange(POINTS) / POINTS)
    crank = result.q[:, :, 2]
    np.testing.assert_allclose(crank - crank[:, :1], np.broadcast_to(result.phase, crank.shape))
    rocker = result.q[:, :, 8]
    # the open branch all the way round: the rocker swings between 1.52 and 2.42 rad
    assert (rocker > 1.5).all() and (rocker < 2.45).all()
    assert np.isfinite(result.omega).all()


def test_run__stores_omega_cycle_with_a_phase_coordinate():
    text = fourbar_text() + '[modes]\nalong = { driver = "crank", points = 6 }\n'
    scene = load_scene_text(text)
    model = compile_model(scene)
    out = solve_chunk(model, scene)
    assert out["omega_cycle"].shape == (1, 6, model.nmode)
    np.testing.assert_allclose(out["cycle_phase"], 2 * np.pi * np.arange(6) / 6)
    start = assemble(model)
    direct = solve_modes_along(model, 0, 6, start.q, start.v)
    np.testing.assert_array_equal(out["omega_cycle"], direct.omega)
