"""Time tables of drivers and loads: cubic splines evaluated in the kernels.

A table ``law = "table"`` is fitted once, when the scene is compiled
(:func:`mcchain.scene.compile.spline_table`), to a piecewise cubic on its knots t_0 < … < t_{n−1}:
on [t_i, t_{i+1}] the value is c_0 + τ (c_1 + τ (c_2 + τ c_3)), τ = t − t_i. The kernels
only evaluate it, with its exact first and second derivatives (the ḟ and f̈ a driver's
velocity and acceleration rows need). The generated lane kernels carry a copy of
:func:`spline_at` and the table as constants.
"""

from __future__ import annotations

from mcchain.kernels.config import JIT, njit


@njit(**JIT)
def spline_at(knots, coef, n, t):
    """(f, ḟ, f̈) at ``t`` of the cubic spline on the first ``n`` ``knots`` (n ≥ 2) with
    ascending coefficients ``coef`` (flat, 4 per segment); beyond the knots the end segments
    are extended (the checks keep runs inside)."""
    lo = 0
    hi = n - 1
    while hi - lo > 1:  # the segment [knots[lo], knots[lo + 1]) that holds t
        mid = (lo + hi) // 2
        if t >= knots[mid]:
            lo = mid
        else:
            hi = mid
    tau = t - knots[lo]
    c0 = coef[4 * lo]
    c1 = coef[4 * lo + 1]
    c2 = coef[4 * lo + 2]
    c3 = coef[4 * lo + 3]
    value = c0 + tau * (c1 + tau * (c2 + tau * c3))
    rate = c1 + tau * (2.0 * c2 + 3.0 * c3 * tau)
    return value, rate, 2.0 * c2 + 6.0 * c3 * tau
