"""Small dense linear algebra for one sample, written to report failure instead of raising.

``np.linalg`` raises on a singular matrix, and a raise would end a whole block of samples
(PERFORMANCE.md), so the batch kernels use these: each works in place on the leading
``n × n`` block of its arrays and returns ``False`` (or a rank) where LAPACK would raise.
"""

from __future__ import annotations

import math

import numpy as np

from mcchain.kernels.config import JIT, njit

EPS = np.finfo(np.float64).eps


@njit(**JIT)
def lu_factor(A, n, piv, rtol):
    """LU with partial pivoting of ``A[:n, :n]`` in place (L unit lower, U upper).

    Returns ``False`` if a pivot is ≤ ``rtol`` × the largest entry of A (singular).
    """
    scale = 0.0
    for i in range(n):
        for j in range(n):
            scale = max(scale, abs(A[i, j]))
    if not scale > 0.0:
        return False
    for k in range(n):
        p = k
        best = abs(A[k, k])
        for i in range(k + 1, n):
            if abs(A[i, k]) > best:
                best = abs(A[i, k])
                p = i
        piv[k] = p
        if not best > rtol * scale:
            return False
        if p != k:
            for j in range(n):
                A[k, j], A[p, j] = A[p, j], A[k, j]
        inv = 1.0 / A[k, k]
        for i in range(k + 1, n):
            A[i, k] *= inv
            f = A[i, k]
            if f != 0.0:
                for j in range(k + 1, n):
                    A[i, j] -= f * A[k, j]
    return True


@njit(**JIT)
def lu_solve(A, n, piv, b):
    """Solve with the factors of :func:`lu_factor`; ``b[:n]`` is overwritten by x."""
    for k in range(n):
        p = piv[k]
        if p != k:
            b[k], b[p] = b[p], b[k]
    for i in range(n):
        acc = b[i]
        for j in range(i):
            acc -= A[i, j] * b[j]
        b[i] = acc
    for i in range(n - 1, -1, -1):
        acc = b[i]
        for j in range(i + 1, n):
            acc -= A[i, j] * b[j]
        b[i] = acc / A[i, i]


@njit(**JIT)
def cholesky(A, n, rtol):
    """Cholesky A = L Lᵀ of ``A[:n, :n]`` in place (lower triangle holds L).

    Returns ``False`` if a pivot is ≤ ``rtol`` × the largest diagonal entry (not positive
    definite to working accuracy).
    """
    scale = 0.0
    for i in range(n):
        scale = max(scale, abs(A[i, i]))
    for j in range(n):
        acc = A[j, j]
        for k in range(j):
            acc -= A[j, k] * A[j, k]
        if not acc > rtol * scale:
            return False
        ljj = math.sqrt(acc)
        A[j, j] = ljj
        for i in range(j + 1, n):
            acc = A[i, j]
            for k in range(j):
                acc -= A[i, k] * A[j, k]
            A[i, j] = acc / ljj
    return True


@njit(**JIT)
def cholesky_solve(L, n, b):
    """Solve L Lᵀ x = b with the factor of :func:`cholesky`; ``b[:n]`` becomes x."""
    for i in range(n):
        acc = b[i]
        for k in range(i):
            acc -= L[i, k] * b[k]
        b[i] = acc / L[i, i]
    for i in range(n - 1, -1, -1):
        acc = b[i]
        for k in range(i + 1, n):
            acc -= L[k, i] * b[k]
        b[i] = acc / L[i, i]


@njit(**JIT)
def null_space(B, m, n, rtol, Q_out, work):
    """Orthonormal basis of the null space of ``B[:m, :n]`` by Householder QR of Bᵀ.

    Column pivoting (largest remaining row of B first) reveals the rank r: a pivot whose norm
    is ≤ ``rtol`` × the first one ends the factorisation. Q_out[:, r:n] then spans
    {z : B z = 0}.

    Args:
        B: (≥m, ≥n) not modified.
        Q_out: (n, n) receives Q; columns r.. are the null-space basis.
        work: (n, m + 1) scratch.

    Returns:
        r, the numerical rank of B.
    """
    A = work  # A = Bᵀ, n × m, reflected in place
    for i in range(n):
        for j in range(m):
            A[i, j] = B[j, i]
    for i in range(n):
        for j in range(n):
            Q_out[i, j] = 1.0 if i == j else 0.0
    first = 0.0
    rank = 0
    for k in range(min(m, n)):
        # pivot: the remaining column of A (row of B) with the largest norm below row k
        best = -1.0
        p = k
        for j in range(k, m):
            acc = 0.0
            for i in range(k, n):
                acc += A[i, j] * A[i, j]
            if acc > best:
                best = acc
                p = j
        norm = math.sqrt(best)
        if k == 0:
            first = norm
        if not norm > rtol * first or norm == 0.0:
            break
        if p != k:
            for i in range(n):
                A[i, k], A[i, p] = A[i, p], A[i, k]
        # Householder vector v = x + sign(x0)|x| e0, stored in column m of work
        alpha = -norm if A[k, k] >= 0.0 else norm
        for i in range(n):
            work[i, m] = 0.0
        for i in range(k, n):
            work[i, m] = A[i, k]
        work[k, m] -= alpha
        vnorm2 = 0.0
        for i in range(k, n):
            vnorm2 += work[i, m] * work[i, m]
        if vnorm2 > 0.0:
            # A ← (I − 2 v vᵀ/vᵀv) A on the remaining columns
            for j in range(k, m):
                acc = 0.0
                for i in range(k, n):
                    acc += work[i, m] * A[i, j]
                f = 2.0 * acc / vnorm2
                for i in range(k, n):
                    A[i, j] -= f * work[i, m]
            # Q ← Q (I − 2 v vᵀ/vᵀv)
            for i in range(n):
                acc = 0.0
                for j in range(k, n):
                    acc += Q_out[i, j] * work[j, m]
                f = 2.0 * acc / vnorm2
                for j in range(k, n):
                    Q_out[i, j] -= f * work[j, m]
        rank += 1
    return rank


@njit(**JIT)
def jacobi_eigh(A, n, w_out, V_out):
    """Eigen-decomposition of the symmetric ``A[:n, :n]`` by cyclic Jacobi rotations.

    A is destroyed. Eigenvalues land in ``w_out[:n]`` ascending, eigenvectors in the
    columns of ``V_out[:n, :n]`` (orthonormal). Absolute accuracy ≈ ε ‖A‖; an exactly
    zero matrix gives exact zeros.

    Returns:
        ``False`` if the sweeps did not converge (non-finite input).
    """
    for i in range(n):
        for j in range(n):
            V_out[i, j] = 1.0 if i == j else 0.0
    total = 0.0
    for i in range(n):
        for j in range(n):
            total += A[i, j] * A[i, j]
    converged = False
    for _sweep in range(100):
        off = 0.0
        for i in range(n):
            for j in range(i + 1, n):
                off += A[i, j] * A[i, j]
        if off <= (EPS * EPS) * total * 1e-4 or off == 0.0:
            converged = True
            break
        for p in range(n - 1):
            for q in range(p + 1, n):
                apq = A[p, q]
                if apq == 0.0:
                    continue
                theta = (A[q, q] - A[p, p]) / (2.0 * apq)
                t = 1.0 / (abs(theta) + math.sqrt(theta * theta + 1.0))
                if theta < 0.0:
                    t = -t
                c = 1.0 / math.sqrt(t * t + 1.0)
                sn = t * c
                for k in range(n):
                    akp = A[k, p]
                    akq = A[k, q]
                    A[k, p] = c * akp - sn * akq
                    A[k, q] = sn * akp + c * akq
                for k in range(n):
                    apk = A[p, k]
                    aqk = A[q, k]
                    A[p, k] = c * apk - sn * aqk
                    A[q, k] = sn * apk + c * aqk
                for k in range(n):
                    vkp = V_out[k, p]
                    vkq = V_out[k, q]
                    V_out[k, p] = c * vkp - sn * vkq
                    V_out[k, q] = sn * vkp + c * vkq
    for i in range(n):
        w_out[i] = A[i, i]
    # insertion sort, ascending, carrying the vectors along
    for i in range(1, n):
        j = i
        while j > 0 and w_out[j - 1] > w_out[j]:
            w_out[j - 1], w_out[j] = w_out[j], w_out[j - 1]
            for k in range(n):
                V_out[k, j - 1], V_out[k, j] = V_out[k, j], V_out[k, j - 1]
            j -= 1
    return converged
