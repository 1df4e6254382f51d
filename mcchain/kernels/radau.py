"""Radau IIA of order 5 (Hairer & Wanner, *Solving ODEs II*, §IV.8), compiled, one sample at
a time, on the index-1 accelerations of :func:`mcchain.kernels.explicit.index1_acceleration`.

A step-for-step port of scipy's ``scipy.integrate.Radau`` (``_ivp/radau.py``, scipy 1.17):
the same collocation Newton iteration in the transformed variables (one real and one complex
LU of n × n), the same embedded error estimate, step-size prediction, Jacobian reuse and
dense output, so that ``radau`` stays scipy's method, the independent reference of the
explicit integrators, without scipy's Python overhead per step (a 30 ms slider-crank with
contact at rtol 1e-11 took over 10 minutes through solve_ivp). The Jacobian of the
right-hand side is formed here by forward differences over the n = 2 ndof state entries
(scipy's ``num_jac`` adapts its increments; only the Newton iteration's convergence depends
on it, never the accepted solution's accuracy).

The driver (:mod:`mcchain.solvers.radau`) calls one compiled entry, :func:`radau_kernel`:
``START`` (:func:`radau_start`) at the start of each segment between events and ``STEP``
(:func:`radau_step`) once per accepted step; it evaluates the accelerations its events,
outputs and peaks read with :func:`mcchain.kernels.explicit.index1_acceleration` itself
(about 4 times a step: an entry of 20 arguments, where this one's 38 cost 1.6 µs more a
call from Python), and locates events and writes outputs on the step's dense output
:func:`radau_dense`.

One stepping entry, and the right-hand side :func:`_rhs` compiled on its own (not inlined):
numba links a callee's code into each compiled caller and keeps it in that caller's cache
file, which a warm run loads and parses again, so two stepping entries held the index-1
accelerations twice, and each inlined call site once more
(``benchmarks/results/speed/warm.md``).

START and STEP leave the accelerations' outputs (q̈, λ and the contact state in ``acc``) at
the state they end at, for the driver's step hook. The stepper's scalars live in ``state``
(:data:`NSTATE`,), indexed by the constants below.
"""

from __future__ import annotations

import math

import numpy as np

from mcchain.kernels.config import INLINE, JIT, njit
from mcchain.kernels.explicit import index1_acceleration
from mcchain.kernels.linalg import lu_factor, lu_solve

_S6 = 6.0**0.5
C = np.array([(4.0 - _S6) / 10.0, (4.0 + _S6) / 10.0, 1.0])
"""Collocation nodes."""
E = np.array([-13.0 - 7.0 * _S6, -13.0 + 7.0 * _S6, -1.0]) / 3.0
"""Weights of the embedded error estimate."""
MU_REAL = 3.0 + 3.0 ** (2.0 / 3.0) - 3.0 ** (1.0 / 3.0)
MU_COMPLEX = (3.0 + 0.5 * (3.0 ** (1.0 / 3.0) - 3.0 ** (2.0 / 3.0))) - 0.5j * (
    3.0 ** (5.0 / 6.0) + 3.0 ** (7.0 / 6.0)
)
"""Eigenvalues of the inverse of the method's matrix A = T Λ T⁻¹ (one real, a conjugate pair)."""
T = np.array(
    [
        [0.09443876248897524, -0.14125529502095421, 0.03002919410514742],
        [0.25021312296533332, 0.20412935229379994, -0.38294211275726192],
        [1.0, 1.0, 0.0],
    ]
)
TI = np.array(
    [
        [4.17871859155190428, 0.32768282076106237, 0.52337644549944951],
        [-4.17871859155190428, -0.32768282076106237, 0.47662355450055044],
        [0.50287263494578682, -2.57192694985560522, 0.59603920482822492],
    ]
)
TI_COMPLEX = TI[1] + 1j * TI[2]
P = np.array(
    [
        [13.0 / 3.0 + 7.0 * _S6 / 3.0, -23.0 / 3.0 - 22.0 * _S6 / 3.0, 10.0 / 3.0 + 5.0 * _S6],
        [13.0 / 3.0 - 7.0 * _S6 / 3.0, -23.0 / 3.0 + 22.0 * _S6 / 3.0, 10.0 / 3.0 - 5.0 * _S6],
        [1.0 / 3.0, -8.0 / 3.0, 10.0 / 3.0],
    ]
)
"""Dense output: y(t_old + x h) = y_old + Q (x, x², x³) with Q = Zᵀ P."""
NEWTON_MAXITER = 6
MIN_FACTOR = 0.2
MAX_FACTOR = 10.0
EPS = float(np.finfo(float).eps)
JACOBIAN_INCREMENT = EPS**0.5
"""Forward-difference increment relative to max(|y_k|, the largest |y| of its half)."""

# state entries
T_NOW, H_ABS, H_ABS_OLD, ERROR_OLD, CURRENT_JAC, LU_OK, SOL_OK, T_OLD, NFEV, T_FAIL = range(10)
NSTATE = 10
"""H_ABS_OLD and ERROR_OLD are NaN where scipy's are None; CURRENT_JAC, LU_OK, SOL_OK are
0/1 flags; NFEV counts right-hand-side evaluations (the Jacobian's not included); T_FAIL is
the time of a singular evaluation."""

ACCEPTED, TOO_SMALL_STEP, SINGULAR_EVALUATION = 0, 1, 2
"""What :func:`radau_kernel` returns."""

START, STEP = 0, 1
"""What :func:`radau_kernel` does (its ``op``)."""


@njit(**JIT)
def _rhs(km, s, t, y, f_out, balpha2, bbeta2, tau, acc):
    """f = (v, q̈) at (t, y = (q, v)); max |Φ|, < 0 (or NaN) where S lost rank (see
    index1_acceleration). Not inlined: one copy of the accelerations serves every call."""
    minv, cols, first, cst, row_law, B, S, F, g, phi, qdd, lam = acc
    n = qdd.shape[0]
    err = index1_acceleration(
        km, s, y[:n], y[n:], t, balpha2, bbeta2, tau, minv, cols, first, cst, row_law, B, S, F,
        g, phi, qdd, lam,
    )  # fmt: skip
    for k in range(n):
        f_out[k] = y[n + k]
        f_out[n + k] = qdd[k]
    return err


@njit(**INLINE)
def _regular(err):
    """Whether an evaluation's max |Φ| says S kept its rank (NaN says it did not)."""
    return err >= 0.0


@njit(**JIT)
def radau_rhs(km, s, t, y, f_out, balpha2, bbeta2, tau, acc):
    """:func:`_rhs` on its own, True where S kept its rank (the tests)."""
    return _regular(_rhs(km, s, t, y, f_out, balpha2, bbeta2, tau, acc))


@njit(**JIT)
def radau_jacobian(km, s, t, y, f, J_out, work_y, work_f, balpha2, bbeta2, tau, acc):
    """∂f/∂y (n, n) at (t, y), f = f(t, y): [[0, I], [∂q̈/∂q, ∂q̈/∂v]], the lower half by
    forward differences; False when an evaluation found S rank-deficient."""
    n = y.shape[0]
    half = n // 2
    for a in range(n):
        for b in range(n):
            J_out[a, b] = 0.0
    for k in range(half):
        J_out[k, half + k] = 1.0
    for k in range(n):
        work_y[k] = y[k]
    for j in range(n):
        lo = 0 if j < half else half
        floor = 0.0
        for k in range(lo, lo + half):
            floor = max(floor, abs(y[k]))
        step = JACOBIAN_INCREMENT * max(abs(y[j]), floor, 1e-300)
        work_y[j] = y[j] + step
        step = work_y[j] - y[j]
        if not _regular(_rhs(km, s, t, work_y, work_f, balpha2, bbeta2, tau, acc)):
            return False
        for k in range(half, n):
            J_out[k, j] = (work_f[k] - f[k]) / step
        work_y[j] = y[j]
    return True


@njit(**INLINE)
def _rms(x, scale):
    acc = 0.0
    for k in range(x.shape[0]):
        acc += (x[k] / scale[k]) ** 2
    return math.sqrt(acc / x.shape[0])


@njit(**INLINE)
def _predict_factor(h_abs, h_abs_old, error_norm, error_norm_old):
    """scipy's ``predict_factor`` (NaN for its None)."""
    if math.isnan(error_norm_old) or math.isnan(h_abs_old) or error_norm == 0.0:
        multiplier = 1.0
    else:
        multiplier = h_abs / h_abs_old * (error_norm_old / error_norm) ** 0.25
    return min(1.0, multiplier) * error_norm**-0.25


@njit(**INLINE)
def _ulp(t):
    """nextafter(|t|, ∞) − |t|."""
    if t == 0.0:
        return 5e-324
    e = math.frexp(abs(t))[1]
    return 2.0 ** (e - 53)


@njit(**JIT)
def radau_dense(t, t_old, h, y_old, Q, y_out):
    """The dense output of the last step (t_old, h, y_old (n,), Q (n, 3)) at t into y_out."""
    x = (t - t_old) / h
    p1 = x
    p2 = x * x
    p3 = p2 * x
    for k in range(y_out.shape[0]):
        y_out[k] = Q[k, 0] * p1 + Q[k, 1] * p2 + Q[k, 2] * p3 + y_old[k]


@njit(**JIT)
def radau_start(km, s, t0, t_bound, y, f, J, rtol, atol, state, work_y, work_f, balpha2, bbeta2,
                tau, acc):  # fmt: skip
    """Start a segment at (t0, y): f, the first step (scipy's ``select_initial_step`` of
    order 3), the Jacobian; ACCEPTED or SINGULAR_EVALUATION."""
    n = y.shape[0]
    state[T_NOW] = t0
    state[H_ABS_OLD] = math.nan
    state[ERROR_OLD] = math.nan
    state[CURRENT_JAC] = 1.0
    state[LU_OK] = 0.0
    state[SOL_OK] = 0.0
    state[NFEV] += 1.0
    if not _regular(_rhs(km, s, t0, y, f, balpha2, bbeta2, tau, acc)):
        state[T_FAIL] = t0
        return SINGULAR_EVALUATION
    interval = abs(t_bound - t0)
    d0 = 0.0
    d1 = 0.0
    for k in range(n):
        sc = atol + abs(y[k]) * rtol
        d0 += (y[k] / sc) ** 2
        d1 += (f[k] / sc) ** 2
    d0 = math.sqrt(d0 / n)
    d1 = math.sqrt(d1 / n)
    h0 = 1e-6 if d0 < 1e-5 or d1 < 1e-5 else 0.01 * d0 / d1
    h0 = min(h0, interval)
    for k in range(n):
        work_y[k] = y[k] + h0 * f[k]
    state[NFEV] += 1.0
    if not _regular(_rhs(km, s, t0 + h0, work_y, work_f, balpha2, bbeta2, tau, acc)):
        state[T_FAIL] = t0 + h0
        return SINGULAR_EVALUATION
    d2 = 0.0
    for k in range(n):
        d2 += ((work_f[k] - f[k]) / (atol + abs(y[k]) * rtol)) ** 2
    d2 = math.sqrt(d2 / n) / h0
    if d1 <= 1e-15 and d2 <= 1e-15:
        h1 = max(1e-6, h0 * 1e-3)
    else:
        h1 = (0.01 / max(d1, d2)) ** (1.0 / 4.0)
    state[H_ABS] = min(100.0 * h0, h1, interval)
    if not radau_jacobian(km, s, t0, y, f, J, work_y, work_f, balpha2, bbeta2, tau, acc):
        state[T_FAIL] = t0
        return SINGULAR_EVALUATION
    _rhs(km, s, t0, y, work_f, balpha2, bbeta2, tau, acc)  # q̈, λ at (t0, y) (not counted)
    return ACCEPTED


@njit(**JIT)
def radau_step(km, s, t_bound, y, f, J, LUr, piv_r, LUc, piv_c, Z, W, F, y_old, Q, rtol, atol,
               state, work_y, work_f, work_c, balpha2, bbeta2, tau, acc):  # fmt: skip
    """One accepted step of scipy's Radau from (state[T_NOW], y) towards ``t_bound``:
    y, f, J and the dense output (state[T_OLD], y_old, Q) updated in place.

    Arrays: y, f, y_old, work_y, work_f (n,) float; J, LUr (n, n) float; LUc (n, n) complex;
    piv_r, piv_c (n,) int64; Z, W, F (3, n) float; Q (n, 3) float; work_c (n,) complex.

    Returns ACCEPTED, TOO_SMALL_STEP (the step fell below 10 ulp of t: scipy's failure) or
    SINGULAR_EVALUATION (S lost rank at the evaluation at state[T_FAIL]).
    """
    n = y.shape[0]
    t = state[T_NOW]
    min_step = 10.0 * _ulp(t)
    h_abs = state[H_ABS]
    h_abs_old = state[H_ABS_OLD]
    error_old = state[ERROR_OLD]
    if h_abs < min_step:
        h_abs = min_step
        h_abs_old = math.nan
        error_old = math.nan
    current_jac = state[CURRENT_JAC] != 0.0
    lu_ok = state[LU_OK] != 0.0
    newton_tol = max(10.0 * EPS / rtol, min(0.03, rtol**0.5))
    rejected = False
    factored = lu_ok
    n_iter = 0
    rate = math.nan
    error_norm = 0.0
    safety = 0.0
    t_new = t
    h = 0.0
    scale = work_y  # the tolerance scale (work_y is free inside the step)
    while True:
        if h_abs < min_step:
            return TOO_SMALL_STEP
        t_new = t + h_abs
        if t_new - t_bound > 0.0:
            t_new = t_bound
        h = t_new - t
        h_abs = abs(h)
        for k in range(n):
            scale[k] = atol + abs(y[k]) * rtol
        converged = False
        while not converged:
            if not lu_ok:
                for a in range(n):
                    for b in range(n):
                        LUr[a, b] = -J[a, b]
                        LUc[a, b] = -J[a, b]
                    LUr[a, a] += MU_REAL / h
                    LUc[a, a] += MU_COMPLEX / h
                # an exactly zero pivot (scipy's LU would give inf): Newton fails
                factored = lu_factor(LUr, n, piv_r, 0.0) and lu_factor(LUc, n, piv_c, 0.0)
                lu_ok = True
            # Z0: the last step's dense output extrapolated to the nodes (0 at a start)
            for i in range(3):
                if state[SOL_OK] != 0.0:
                    radau_dense(t + h * C[i], state[T_OLD], t - state[T_OLD], y_old, Q, work_f)
                    for k in range(n):
                        Z[i, k] = work_f[k] - y[k]
                else:
                    for k in range(n):
                        Z[i, k] = 0.0
            code, n_iter, rate = 0, 1, math.nan
            if factored:
                code, n_iter, rate = _collocation(
                    km, s, t, y, h, Z, W, F, scale, newton_tol, LUr, piv_r, LUc, piv_c, state,
                    work_f, work_c, balpha2, bbeta2, tau, acc,
                )  # fmt: skip
            if code < 0:
                return SINGULAR_EVALUATION
            converged = code > 0
            if not converged:
                if current_jac:
                    break
                if not radau_jacobian(km, s, t, y, f, J, F[0], work_f, balpha2, bbeta2, tau,
                                      acc):  # fmt: skip
                    state[T_FAIL] = t
                    return SINGULAR_EVALUATION
                current_jac = True
                lu_ok = False
        if not converged:
            h_abs *= 0.5
            lu_ok = False
            continue
        # error estimate: (f + Zᵀ E / h) through the real LU
        for k in range(n):
            work_f[k] = f[k] + (Z[0, k] * E[0] + Z[1, k] * E[1] + Z[2, k] * E[2]) / h
            F[1, k] = work_f[k] - f[k]  # ZE, kept for a second estimate
        lu_solve(LUr, n, piv_r, work_f)
        for k in range(n):
            scale[k] = atol + max(abs(y[k]), abs(y[k] + Z[2, k])) * rtol
        error_norm = _rms(work_f, scale)
        safety = 0.9 * (2 * NEWTON_MAXITER + 1) / (2 * NEWTON_MAXITER + n_iter)
        if rejected and error_norm > 1.0:
            for k in range(n):
                F[0, k] = y[k] + work_f[k]
            state[NFEV] += 1.0
            if not _regular(_rhs(km, s, t, F[0], F[2], balpha2, bbeta2, tau, acc)):
                state[T_FAIL] = t
                return SINGULAR_EVALUATION
            for k in range(n):
                work_f[k] = F[2, k] + F[1, k]
            lu_solve(LUr, n, piv_r, work_f)
            error_norm = _rms(work_f, scale)
        if error_norm > 1.0:
            factor = _predict_factor(h_abs, h_abs_old, error_norm, error_old)
            h_abs *= max(MIN_FACTOR, safety * factor)
            lu_ok = False
            rejected = True
        else:
            break
    recompute_jac = n_iter > 2 and rate > 1e-3
    factor = _predict_factor(h_abs, h_abs_old, error_norm, error_old)
    factor = min(MAX_FACTOR, safety * factor)
    if not recompute_jac and factor < 1.2:
        factor = 1.0
    else:
        lu_ok = False
    for k in range(n):
        y_old[k] = y[k]
        y[k] = y[k] + Z[2, k]
    state[NFEV] += 1.0
    if not _regular(_rhs(km, s, t_new, y, f, balpha2, bbeta2, tau, acc)):
        state[T_FAIL] = t_new
        return SINGULAR_EVALUATION
    if recompute_jac:
        if not radau_jacobian(km, s, t_new, y, f, J, F[0], work_f, balpha2, bbeta2, tau, acc):
            state[T_FAIL] = t_new
            return SINGULAR_EVALUATION
        _rhs(km, s, t_new, y, work_f, balpha2, bbeta2, tau, acc)  # q̈, λ at the step's end
        current_jac = True
    else:
        current_jac = False
    state[H_ABS_OLD] = state[H_ABS]
    state[ERROR_OLD] = error_norm
    state[H_ABS] = h_abs * factor
    state[T_OLD] = t
    state[T_NOW] = t_new
    state[CURRENT_JAC] = 1.0 if current_jac else 0.0
    state[LU_OK] = 1.0 if lu_ok else 0.0
    state[SOL_OK] = 1.0
    for k in range(n):
        for j in range(3):
            Q[k, j] = Z[0, k] * P[0, j] + Z[1, k] * P[1, j] + Z[2, k] * P[2, j]
    return ACCEPTED


@njit(**JIT)
def radau_kernel(op, t, km, s, t_bound, y, f, J, LUr, piv_r, LUc, piv_c, Z, W, F, y_old, Q,
                 rtol, atol, state, work_y, work_f, work_c, balpha2, bbeta2, tau, minv, cols,
                 first, cst, row_law, work_B, work_S, work_F, work_g, work_phi, qdd_out,
                 lam_out):  # fmt: skip
    """The driver's one compiled stepping entry: ``op`` START (:func:`radau_start` of a
    segment at (t, y) towards ``t_bound``) or STEP (:func:`radau_step` towards ``t_bound``;
    ``t`` unread). Arrays as :func:`radau_step`'s, then the accelerations' (``acc``, as
    :func:`mcchain.kernels.explicit.index1_acceleration` takes them) one by one, not as a
    tuple, which numba takes from Python more slowly. Returns what the operation returns."""
    acc = (minv, cols, first, cst, row_law, work_B, work_S, work_F, work_g, work_phi, qdd_out,
           lam_out)  # fmt: skip
    if op == START:
        return radau_start(km, s, t, t_bound, y, f, J, rtol, atol, state, work_y, work_f,
                           balpha2, bbeta2, tau, acc)  # fmt: skip
    return radau_step(km, s, t_bound, y, f, J, LUr, piv_r, LUc, piv_c, Z, W, F, y_old, Q,
                      rtol, atol, state, work_y, work_f, work_c, balpha2, bbeta2, tau,
                      acc)  # fmt: skip


@njit(**INLINE)
def _collocation(km, s, t, y, h, Z, W, F, scale, tol, LUr, piv_r, LUc, piv_c, state, work_f,
                 work_c, balpha2, bbeta2, tau, acc):  # fmt: skip
    """scipy's ``solve_collocation_system``: simplified Newton on the stage increments Z
    (3, n; the guess in, the solution out) in the variables W = T⁻¹ Z. Returns (1 converged,
    0 not, −1 singular evaluation at state[T_FAIL]; iterations; the rate, NaN if none)."""
    n = y.shape[0]
    m_real = MU_REAL / h
    m_complex = MU_COMPLEX / h
    for i in range(3):
        for k in range(n):
            W[i, k] = TI[i, 0] * Z[0, k] + TI[i, 1] * Z[1, k] + TI[i, 2] * Z[2, k]
    dw_norm_old = math.nan
    rate = math.nan
    k_iter = 0
    for k_iter in range(NEWTON_MAXITER):
        finite = True
        for i in range(3):
            for k in range(n):
                work_f[k] = y[k] + Z[i, k]
            state[NFEV] += 1.0
            if not _regular(_rhs(km, s, t + h * C[i], work_f, F[i], balpha2, bbeta2, tau, acc)):
                state[T_FAIL] = t + h * C[i]
                return -1, k_iter + 1, rate
            for k in range(n):
                if not math.isfinite(F[i, k]):
                    finite = False
        if not finite:
            break
        for k in range(n):
            work_f[k] = (
                F[0, k] * TI[0, 0] + F[1, k] * TI[0, 1] + F[2, k] * TI[0, 2] - m_real * W[0, k]
            )
            work_c[k] = (
                F[0, k] * TI_COMPLEX[0]
                + F[1, k] * TI_COMPLEX[1]
                + F[2, k] * TI_COMPLEX[2]
                - m_complex * (W[1, k] + 1j * W[2, k])
            )
        lu_solve(LUr, n, piv_r, work_f)
        lu_solve(LUc, n, piv_c, work_c)
        acc2 = 0.0
        for k in range(n):
            acc2 += (work_f[k] / scale[k]) ** 2
            acc2 += (work_c[k].real / scale[k]) ** 2
            acc2 += (work_c[k].imag / scale[k]) ** 2
        dw_norm = math.sqrt(acc2 / (3 * n))
        if not math.isnan(dw_norm_old):
            rate = dw_norm / dw_norm_old
        if not math.isnan(rate) and (
            rate >= 1.0 or rate ** (NEWTON_MAXITER - k_iter) / (1.0 - rate) * dw_norm > tol
        ):
            return 0, k_iter + 1, rate
        for k in range(n):
            W[0, k] += work_f[k]
            W[1, k] += work_c[k].real
            W[2, k] += work_c[k].imag
        for i in range(3):
            for k in range(n):
                Z[i, k] = T[i, 0] * W[0, k] + T[i, 1] * W[1, k] + T[i, 2] * W[2, k]
        if dw_norm == 0.0 or (not math.isnan(rate) and rate / (1.0 - rate) * dw_norm < tol):
            return 1, k_iter + 1, rate
        dw_norm_old = dw_norm
    return 0, k_iter + 1, rate
