"""Body outlines and world positions drawn by the viewer (mcchain.viz.geometry)."""

from __future__ import annotations

import numpy as np
from test_viz_synthetic import HALF, make_dataset, make_model, random_params

from mcchain.viz import geometry

EXACT = 1e-12  # float64 round-off of a rotation and a sum


def test_outline_strips__collinear_points_make_one_sorted_strip() -> None:
    points = np.array([[0.0, 0.0], [0.5, 0.0], [-0.5, 0.0], [0.25, 0.0]])
    (strip,) = geometry.outline_strips(points)
    np.testing.assert_array_equal(strip[:, 0], [-0.5, 0.0, 0.25, 0.5])


def test_outline_strips__plate_is_a_closed_hull_with_a_spoke_to_the_centre() -> None:
    points = np.array([[0.0, 0.0], [1.0, -0.5], [0.0, 1.0], [-1.0, -0.5]])
    hull, spoke = geometry.outline_strips(points)
    assert len(hull) == 4 and np.array_equal(hull[0], hull[-1])
    assert {tuple(p) for p in hull[:-1]} == {(1.0, -0.5), (0.0, 1.0), (-1.0, -0.5)}
    assert tuple(spoke[0]) == (0.0, 0.0) and tuple(spoke[1]) in {tuple(p) for p in hull}


def test_outline_strips__a_lone_centre_of_mass_is_a_degenerate_strip() -> None:
    (strip,) = geometry.outline_strips(np.zeros((1, 2)))
    assert strip.shape == (2, 2)


def test_body_local_points__collects_joints_springs_forces_and_the_centre() -> None:
    model = make_model(random_params(3))
    crank = geometry.body_local_points(model, 0)
    bar = geometry.body_local_points(model, 1)
    assert {tuple(p) for p in crank} == {(0.0, 0.0), (-HALF, 0.0), (HALF, 0.0)}
    # bar: centre, joint A journal, spring end, force point (= the far end)
    assert {tuple(p) for p in bar} == {(0.0, 0.0), (-HALF, 0.0), (0.25, 0.0), (HALF, 0.0)}
    outlines = geometry.body_outlines(model)
    assert [o.name for o in outlines] == ["crank", "bar"]
    assert all(len(o.strips) == 1 for o in outlines)


def test_to_world__rotation_then_translation() -> None:
    pose = np.array([[1.0, 2.0, np.pi / 2], [0.0, 0.0, 0.0]])
    world = geometry.to_world(np.array([[1.0, 0.0], [0.0, 2.0]]), pose)
    np.testing.assert_allclose(world[0], [[1.0, 3.0], [-1.0, 2.0]], atol=EXACT)
    np.testing.assert_allclose(world[1], [[1.0, 0.0], [0.0, 2.0]], atol=EXACT)


def test_joint_track__ideal_joint_closes_and_clearance_offset_is_magnified() -> None:
    params = random_params(3)
    ds = make_dataset(params, history_dtype=np.float64)
    model = make_model(params)
    magnify = 100.0
    for row in range(3):
        q = ds["q"].values[row]
        jt = geometry.joint_track(model, row, q, magnify)
        c = params[row, 0]
        # ideal joint A: journal on the bar == bearing on the crank
        np.testing.assert_allclose(jt.journal[:, 1], jt.bearing[:, 1], atol=EXACT)
        np.testing.assert_array_equal(jt.drawn[:, 1], jt.journal[:, 1])
        # clearance joint O: |d| = c, drawn magnify·c from the (ground) bearing
        np.testing.assert_allclose(np.linalg.norm(jt.journal[:, 0] - jt.bearing[:, 0], axis=1), c)
        np.testing.assert_allclose(
            np.linalg.norm(jt.drawn[:, 0] - jt.bearing[:, 0], axis=1), magnify * c, rtol=1e-9
        )
        assert jt.circle_radius[0] == magnify * c and jt.circle_radius[1] == 0.0


def test_circles__radius_and_closure() -> None:
    ring = geometry.circles(np.array([[1.0, 2.0]]), 0.5)
    np.testing.assert_allclose(np.linalg.norm(ring[0] - [1.0, 2.0], axis=1), 0.5)
    np.testing.assert_allclose(ring[0, 0], ring[0, -1], atol=EXACT)


def test_characteristic_length__two_one_metre_bars() -> None:
    assert geometry.characteristic_length(make_model(random_params(1))) == 1.0
