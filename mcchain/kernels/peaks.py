"""Continuous per-sample peaks of the reactions, tracked at every step (not from stored points).

A force can reach its maximum inside a step (an impact's peak, a joint force's crest): its
largest value at step ends is low by up to f''h²/8. Every kernel therefore feeds each
tracked quantity's value at every accepted state (t_n, f_n) to :func:`peak_feed`, which keeps
the last four and, where the middle of the four steps holds a local maximum of the data
(f rises into it and falls out of it), locates the maximum of the cubic through the four
points on that step (:func:`cubic_peak`). The interpolation error is O(h⁴ f'''') -- the
order of the RK4 / Dormand-Prince step's own error -- where the largest value at step ends
errs by O(h² f''). The first and last steps of a run are checked with the first and last
four points (:func:`peak_feed`, :func:`peak_last`).

Quantities (the per-sample variables of :mod:`mcchain.ensemble.registry`), per joint k and
driver d, from the multipliers λ at the state (:func:`peak_values`):

* |f_k|, the magnitude of ``joint_force``: √(λ_r² + λ_{r+1}²) for an ideal revolute joint,
  |λ_r| for a prismatic one (the force normal to its axis; its couple is not included) and a
  clearance joint on the link, max(λ_r, 0) = F_n under the contact law (the contact force);
* |λ| of each driver row: the torque of an angle driver (N m), the force along the axis of a
  slider driver (N).

State of one quantity: five numbers ``f_a, f_b, f_c, f_d, peak`` (the last four values,
oldest first, and the running peak), ``stride`` apart in a flat array so that the loop
kernels (one sample, stride 1) and the generated lanes (the work array W, stride LMAX) share
these functions; the four times and the count of points fed are kept once per sample.
Rules every kernel keeps: scalars and flat arrays, no allocation, never raise.
"""

from __future__ import annotations

import math

from mcchain.codes import JOINT_IDEAL, JOINT_PRISMATIC
from mcchain.kernels.config import INLINE, JIT, hypot, njit
from mcchain.kernels.tableaux import PEAK_CLOCK, PEAK_WIDTH

__all__ = ["PEAK_CLOCK", "PEAK_WIDTH"]


@njit(**JIT)
def cubic_peak(ta, fa, tb, fb, tc, fc, td, fd, interval):
    """Largest value of the cubic through (ta, fa) … (td, fd) (ta < tb < tc < td) on the
    step [ta, tb] (``interval`` 0), [tb, tc] (1) or [tc, td] (2), its ends included.

    The maximum is located where p' = 0 inside the step (p' a quadratic, solved in closed
    form). A cubic through data with a kink can overshoot; the answer is capped at
    max f + (max f − min f) of the four points, a bound that a smooth peak sampled four
    times (gain at most f''h²/8 against a spread of at least f''h²/2) never reaches."""
    lo = ta if interval == 0 else (tb if interval == 1 else tc)
    hi = tb if interval == 0 else (tc if interval == 1 else td)
    best = max(fa if interval == 0 else (fb if interval == 1 else fc),
               fb if interval == 0 else (fc if interval == 1 else fd))  # fmt: skip
    d1 = (fb - fa) / (tb - ta)
    d2 = (fc - fb) / (tc - tb)
    d3 = (fd - fc) / (td - tc)
    e1 = (d2 - d1) / (tc - ta)
    e2 = (d3 - d2) / (td - tb)
    g = (e2 - e1) / (td - ta)
    xb = tb - ta
    xc = tc - ta
    # p(u) = fa + d1 u + e1 u (u − xb) + g u (u − xb)(u − xc), u = t − ta; p'(u) = A u² + B u + C
    qa = 3.0 * g
    qb = 2.0 * (e1 - g * (xb + xc))
    qc = d1 - e1 * xb + g * xb * xc
    u1 = math.nan
    u2 = math.nan
    if qa == 0.0:
        if qb != 0.0:
            u1 = -qc / qb
    else:
        disc = qb * qb - 4.0 * qa * qc
        if disc >= 0.0:
            root = math.sqrt(disc)
            qq = -0.5 * (qb + root) if qb >= 0.0 else -0.5 * (qb - root)
            if qq != 0.0:
                u1 = qq / qa
                u2 = qc / qq
            else:
                u1 = 0.0
    ulo = lo - ta
    uhi = hi - ta
    if u1 > ulo and u1 < uhi:
        best = max(best, fa + d1 * u1 + e1 * u1 * (u1 - xb) + g * u1 * (u1 - xb) * (u1 - xc))
    if u2 > ulo and u2 < uhi:
        best = max(best, fa + d1 * u2 + e1 * u2 * (u2 - xb) + g * u2 * (u2 - xb) * (u2 - xc))
    top = max(max(fa, fb), max(fc, fd))
    low = min(min(fa, fb), min(fc, fd))
    return min(best, top + (top - low))


@njit(**INLINE)
def peak_checks(count, fb, fc, fd, f):
    """Which steps the point ``f`` just fed (after f_b, f_c, f_d; ``count`` points before it)
    has the cubic (:func:`cubic_peak`) checked: ``interior`` 1.0 when, with three earlier
    points, the data rise into the step [tc, td] and fall out of it (f_c ≥ f_b, f_d ≥ f, not
    both equal), else 0.0; ``first`` 1.0 when exactly three points came before (the first
    step [tb, tc], once), else 0.0. Straight-line: the generated lanes inline it."""
    interior = 1.0 if count >= 3.0 and fc >= fb and fd >= f and (fc > fb or fd > f) else 0.0
    first = 1.0 if count == 3.0 else 0.0
    return interior, first


@njit(**JIT)
def peak_feed(W, base, stride, count, tb, tc, td, t, f):
    """Feed the value ``f`` at time ``t`` (> ``td``) to the quantity stored at ``W[base]``,
    ``W[base + stride]``, … (:data:`PEAK_WIDTH` numbers: f_a, f_b, f_c, f_d, peak).

    ``tb``, ``tc``, ``td`` are the times of the last three values fed and ``count`` how many
    were fed (at most 4 counts; the oldest of the four kept is dropped here). The peak takes
    ``f``; with three earlier points, the step [tc, td] is checked for an interior maximum
    when the data rise into it and fall out of it (f_c ≥ f_b, f_d ≥ f, not both equal), and
    the first step [tb, tc] once, when exactly three points came before. The caller shifts
    the times after feeding every quantity."""
    fb = W[base + stride]
    fc = W[base + 2 * stride]
    fd = W[base + 3 * stride]
    peak = W[base + 4 * stride]
    peak = max(peak, f)
    interior, first = peak_checks(count, fb, fc, fd, f)
    if interior > 0.0:
        peak = max(peak, cubic_peak(tb, fb, tc, fc, td, fd, t, f, 1))
    if first > 0.0:
        peak = max(peak, cubic_peak(tb, fb, tc, fc, td, fd, t, f, 0))
    W[base] = fb
    W[base + stride] = fc
    W[base + 2 * stride] = fd
    W[base + 3 * stride] = f
    W[base + 4 * stride] = peak


@njit(**JIT)
def peak_last(W, base, stride, count, ta, tb, tc, td):
    """The quantity's peak at the end of the run: the running peak, and the last step
    [tc, td] checked on the cubic through the last four points (if four were fed)."""
    peak = W[base + 4 * stride]
    if count >= 4.0:
        fa = W[base]
        fb = W[base + stride]
        fc = W[base + 2 * stride]
        fd = W[base + 3 * stride]
        peak = max(peak, cubic_peak(ta, fa, tb, fb, tc, fc, td, fd, 2))
    return peak


# -- the loop kernels and radau: one sample's state ``pk`` (PEAK_WIDTH npk + PEAK_CLOCK,) ------


@njit(**JIT)
def peaks_start(pk):
    """Empty state: no point fed, peaks 0 (a magnitude is ≥ 0)."""
    for i in range(pk.shape[0]):
        pk[i] = 0.0


@njit(**JIT)
def peak_values(km, lam, cst, out):
    """The tracked quantities at a state with multipliers ``lam`` (module docstring): |f_k|
    per joint, then |λ| per driver, into ``out`` (njoint + ndriver,). ``cst``: the
    contact-law joints' state (:mod:`mcchain.kernels.clearance`; its column 0 the mode)."""
    nj = km.joint_body_a.shape[0]
    j = 0
    for k in range(nj):
        r = km.joint_row[k]
        if km.joint_kind[k] == JOINT_IDEAL:
            out[k] = hypot(lam[r], lam[r + 1])
        elif km.joint_kind[k] == JOINT_PRISMATIC:
            out[k] = abs(lam[r])
        elif km.joint_model[k] != 0:
            out[k] = abs(lam[r]) if cst[j, 0] == 0.0 else max(lam[r], 0.0)
            j += 1
        else:
            out[k] = abs(lam[r])
    for d in range(km.driver_row.shape[0]):
        out[nj + d] = abs(lam[km.driver_row[d]])


@njit(**JIT)
def peaks_feed(pk, values, t):
    """Feed every quantity's value at time ``t`` (``values`` from :func:`peak_values`);
    a time not after the last one fed is skipped (a rejected step's repeated state)."""
    npk = values.shape[0]
    clock = PEAK_WIDTH * npk
    count = pk[clock + 4]
    if count > 0.0 and not (t > pk[clock + 3]):
        return
    tb, tc, td = pk[clock + 1], pk[clock + 2], pk[clock + 3]
    for k in range(npk):
        peak_feed(pk, PEAK_WIDTH * k, 1, count, tb, tc, td, t, values[k])
    pk[clock] = tb
    pk[clock + 1] = tc
    pk[clock + 2] = td
    pk[clock + 3] = t
    pk[clock + 4] = min(count + 1.0, 4.0)


@njit(**JIT)
def peaks_finish(s, failed, pk, npk, peaks_out):
    """Sample ``s``'s peaks into ``peaks_out[s, :npk]``: NaN after a failure."""
    clock = PEAK_WIDTH * npk
    count = pk[clock + 4]
    ta, tb, tc, td = pk[clock], pk[clock + 1], pk[clock + 2], pk[clock + 3]
    for k in range(npk):
        peak = peak_last(pk, PEAK_WIDTH * k, 1, count, ta, tb, tc, td)
        peaks_out[s, k] = math.nan if failed or count == 0.0 else peak
