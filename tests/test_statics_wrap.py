"""Stored equilibrium angles are wrapped to (−π, π]: one configuration, one value."""

from __future__ import annotations

import math

import numpy as np

from mcchain.scene import compile_model, load_scene_text
from mcchain.solvers import solve_chunk, wrap_angles
from mcchain.testing.factory import paper_bar_text


def test_wrap_angles__boundaries_and_positions_untouched():
    q = np.array([[0.5, -0.25, math.pi, 0.0, 0.0, -math.pi, 1.0, 2.0, 3 * math.pi + 0.1]])
    out = wrap_angles(q)
    np.testing.assert_array_equal(out[0, [0, 1, 3, 4, 6, 7]], q[0, [0, 1, 3, 4, 6, 7]])
    np.testing.assert_allclose(out[0, 2::3], [math.pi, math.pi, -math.pi + 0.1], atol=1e-15)
    assert ((out[0, 2::3] > -math.pi) & (out[0, 2::3] <= math.pi)).all()


def test_equilibrium__a_bar_written_a_turn_away_is_stored_hanging_at_minus_half_pi():
    text = paper_bar_text()
    hanging = "angle = -1.5707963267948966"
    assert hanging in text
    scene = load_scene_text(text.replace(hanging, f"angle = {1.5 * math.pi!r}"))
    out = solve_chunk(compile_model(scene), scene)
    assert abs(out["q_eq"][0, 0, 2] + math.pi / 2) <= 1e-12
