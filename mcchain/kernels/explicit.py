"""Explicit Runge–Kutta on the generic kernels: the loop path, one sample at a time.

The generated lane kernels (:mod:`mcchain.codegen`) are straight-line code per topology:
fastest per step, but every new topology compiles a new module. This module integrates
any topology with the per-sample kernels of ``joints.py``, ``forces.py`` and ``linalg.py``
(the Schur complement S = B M⁻¹ Bᵀ formed over B's non-zeros and factored in its envelope),
so it compiles once per installation. It
follows the lanes' fixed-step RK4 step by step (``[simulate] kernels = "loop"``): the same
stages, the same failure checks at each step's start (max |Φ| past the tolerance: DIVERGED;
rank loss in a stage: SINGULAR at the step's end; λ ≤ 0 at a clearance joint: CONTACT_LOST)
and the same outputs from the first stage's λ. Rules every kernel keeps: no reduction
across samples, never raise, NaN from a failure on.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from mcchain.kernels.assembly import max_abs
from mcchain.kernels.config import JIT
from mcchain.kernels.forces import applied_forces, kinetic_energy, mass_diagonal, potential_energy
from mcchain.kernels.implicit import _nan_history
from mcchain.kernels.joints import (
    constraint_gamma,
    constraint_jacobian,
    constraint_residual,
    constraint_velocity_rhs,
    joint_forces,
)
from mcchain.model import JOINT_CLEARANCE
from mcchain.status import CONTACT_LOST, DIVERGED, FAILURE_BITS, SINGULAR


@njit(**JIT)
def ldl_factor(S, m, first, tau, dinv_out):
    """LDLᵀ of ``S[:m, :m]`` in place (unit L below the diagonal) and ``dinv_out`` = 1/D, in
    the envelope ``first`` (row i holds its non-zeros from column ``first[i]`` on; an LDLᵀ
    fills nothing outside it, so entries outside are never read).

    A pivot D_j ≤ ``tau`` × S_jj is dropped (1/D_j = 0: row j counts as dependent on the
    previous ones), as the generated lanes do. Returns the number of dropped pivots.
    """
    dropped = 0
    for j in range(m):
        diag = S[j, j]
        acc = diag
        for k in range(first[j], j):
            acc -= S[j, k] * S[j, k] * S[k, k]
        ok = acc > tau * diag
        dropped += 0 if ok else 1
        dinv_out[j] = 1.0 / acc if ok else 0.0
        S[j, j] = acc  # D_j; L_jk (k < j) below the diagonal
        for i in range(j + 1, m):
            if first[i] > j:
                continue
            acc_i = S[i, j]
            for k in range(max(first[i], first[j]), j):
                acc_i -= S[i, k] * S[j, k] * S[k, k]
            S[i, j] = acc_i * dinv_out[j]
    return dropped


@njit(**JIT)
def ldl_solve(L, m, first, dinv, b):
    """Solve L D Lᵀ x = b with :func:`ldl_factor`'s factors; ``b[:m]`` becomes x."""
    for i in range(m):
        acc = b[i]
        for k in range(first[i], i):
            acc -= L[i, k] * b[k]
        b[i] = acc
    for i in range(m):
        b[i] *= dinv[i]
    for i in range(m - 1, -1, -1):
        acc = b[i]
        for k in range(i + 1, m):
            if first[k] <= i:
                acc -= L[k, i] * b[k]
        b[i] = acc


@njit(**JIT)
def index1_acceleration(km, s, q, v, t, balpha2, bbeta2, tau, minv, cols, first, work_B,
                        work_S, work_F, work_g, work_phi, qdd_out, lam_out):  # fmt: skip
    """q̈ and λ of M q̈ + Bᵀλ = F, B q̈ = γ − 2α Φ̇ − β² Φ at (q, v, t) for one sample.

    ``minv`` (ndof,) is M⁻¹; ``cols`` (ncon, 6) the columns where each row of B may be
    non-zero (−1 after the last) and ``first`` (ncon,) the envelope of S
    (:meth:`mcchain.model.Model.constraint_pattern`): every product below runs over the
    non-zeros only, so a step costs O(ncon · band²), not O(ncon² ndof). ``work_*`` are scratch
    of shapes (ncon, ndof), (ncon, ncon), (ndof,), (ncon,), (ncon,).
    λ = S⁻¹ (B M⁻¹ F − γ′), q̈ = M⁻¹ (F − Bᵀλ); the sums skip exact zeros only, so the values
    are those of the dense products.

    Returns:
        max |Φ| at (q, t), or −1 − max |Φ| when S lost rank (a pivot ≤ ``tau`` × its
        diagonal entry: that row's λ is 0, the basic solution, as the lanes' LDLᵀ).
    """
    n = q.shape[0]
    m = lam_out.shape[0]
    width = cols.shape[1]
    applied_forces(km, s, q, v, t, work_F)
    constraint_residual(km, s, q, t, work_phi)
    err = max_abs(work_phi, m)
    for k in range(n):
        qdd_out[k] = work_F[k]
    if m > 0:
        constraint_jacobian(km, s, q, work_B)
        constraint_gamma(km, s, q, v, t, work_g)
        constraint_velocity_rhs(km, s, t, lam_out)  # ν, then Φ̇ = B q̇ − ν (drivers: −Φ_t)
        for r in range(m):
            rate = -lam_out[r]
            for c in range(width):
                k = cols[r, c]
                if k < 0:
                    break
                rate += work_B[r, k] * v[k]
            work_g[r] -= balpha2 * rate + bbeta2 * work_phi[r]
        for i in range(m):
            for j in range(first[i], i + 1):
                acc = 0.0
                for c in range(width):
                    k = cols[i, c]
                    if k < 0:
                        break
                    acc += work_B[i, k] * minv[k] * work_B[j, k]
                work_S[i, j] = acc
                work_S[j, i] = acc
        dropped = ldl_factor(work_S, m, first, tau, work_phi)
        for r in range(m):
            acc = -work_g[r]
            for c in range(width):
                k = cols[r, c]
                if k < 0:
                    break
                acc += work_B[r, k] * minv[k] * work_F[k]
            lam_out[r] = acc
        ldl_solve(work_S, m, first, work_phi, lam_out)
        if dropped > 0:
            err = -err - 1.0  # a negative value: S lost rank (err is ≥ 0 otherwise)
        for r in range(m):
            for c in range(width):
                k = cols[r, c]
                if k < 0:
                    break
                qdd_out[k] -= work_B[r, k] * lam_out[r]
    for k in range(n):
        qdd_out[k] = minv[k] * qdd_out[k]
    return err


@njit(**JIT)
def rk4_run(
    start, stop, km, Q0, V0, t0, h, nstep, out_every, ncon, cols, first, A, bw, cc, balpha2,
    bbeta2, ctol, tau, out_q, out_v, out_jf, out_cf, out_dtq, out_cerr, out_en, status, t_div,
    t_sing, t_cl,
):  # fmt: skip
    """Fixed-step RK4 (tableau ``A``, ``bw``, ``cc``, strictly sub-diagonal) with Baumgarte
    on the samples ``start:stop``; outputs every ``out_every`` steps, at t0 + n h. ``cols``,
    ``first``: the constraint pattern (:func:`index1_acceleration`)."""
    ndof = Q0.shape[1]
    nj = km.joint_body_a.shape[0]
    nstage = bw.shape[0]
    for s in range(start, stop):
        if status[s] & FAILURE_BITS:
            _nan_history(s, 0, out_q, out_v, out_jf, out_cf, out_dtq, out_cerr, out_en)
            continue
        q = Q0[s].copy()
        v = V0[s].copy()
        minv = np.zeros(ndof)
        mass_diagonal(km, s, minv)
        for i in range(ndof):
            minv[i] = 1.0 / minv[i]
        B = np.zeros((ncon, ndof))
        S = np.zeros((ncon, ncon))
        F = np.zeros(ndof)
        g = np.zeros(ncon)
        phi = np.zeros(ncon)
        lam = np.zeros(ncon)
        lam0 = np.zeros(ncon)
        qdd = np.zeros(ndof)
        qs = np.zeros(ndof)  # a stage's state
        vs = np.zeros(ndof)
        kq = np.zeros(ndof)  # the previous stage's slopes
        kv = np.zeros(ndof)
        dq = np.zeros(ndof)  # the step's increment, accumulated stage by stage
        dv = np.zeros(ndof)
        jf = np.zeros((nj, 2))
        cf = np.zeros(nj)
        st = status[s]
        pending = False  # a later stage of the previous step lost rank
        written = 0
        for n in range(nstep + 1):
            t = t0 + n * h
            nst = nstage if n < nstep else 1
            err0 = 0.0
            singular = pending
            pending = False
            for stage in range(nst):
                ts = t + cc[stage] * h
                ah = A[stage, stage - 1] * h if stage > 0 else 0.0
                bh = bw[stage] * h
                for i in range(ndof):
                    qs[i] = q[i] + ah * kq[i] if stage > 0 else q[i]
                    vs[i] = v[i] + ah * kv[i] if stage > 0 else v[i]
                err = index1_acceleration(
                    km, s, qs, vs, ts, balpha2, bbeta2, tau, minv, cols, first, B, S, F, g, phi,
                    qdd, lam,
                )  # fmt: skip
                if err < 0.0:
                    err = -err - 1.0
                    if stage == 0:
                        singular = True
                    else:
                        pending = True  # flagged at the step's end, as the lanes do
                for i in range(ndof):
                    kq[i] = vs[i]
                    kv[i] = qdd[i]
                    dq[i] = (dq[i] if stage > 0 else 0.0) + bh * kq[i]
                    dv[i] = (dv[i] if stage > 0 else 0.0) + bh * kv[i]
                if stage == 0:
                    err0 = err
                    for r in range(ncon):
                        lam0[r] = lam[r]
            # failures, once per step at its start (a singular stage: at the step's end)
            bad_div = not (err0 <= ctol)
            for i in range(ndof):
                if not (q[i] == q[i] and v[i] == v[i]):
                    bad_div = True
            if bad_div or singular:
                if singular:
                    st |= SINGULAR
                    t_sing[s] = t
                if bad_div:
                    st |= DIVERGED
                    t_div[s] = t
                break
            if not st & CONTACT_LOST:
                for k in range(nj):
                    if km.joint_kind[k] == JOINT_CLEARANCE and lam0[km.joint_row[k]] <= 0.0:
                        st |= CONTACT_LOST
                        t_cl[s] = t
                        break
            if n % out_every == 0:
                it = n // out_every
                joint_forces(km, s, q, lam0, jf, cf)
                for i in range(ndof):
                    out_q[s, it, i] = q[i]
                    out_v[s, it, i] = v[i]
                for k in range(nj):
                    out_jf[s, it, 2 * k] = jf[k, 0]
                    out_jf[s, it, 2 * k + 1] = jf[k, 1]
                    out_cf[s, it, k] = cf[k]
                for d in range(km.driver_row.shape[0]):
                    out_dtq[s, it, d] = -lam0[km.driver_row[d]]
                out_cerr[s, it] = err0
                out_en[s, it] = kinetic_energy(km, s, v) + potential_energy(km, s, q)
                written = it + 1
            if n == nstep:
                break
            for i in range(ndof):
                q[i] += dq[i]
                v[i] += dv[i]
        _nan_history(s, written, out_q, out_v, out_jf, out_cf, out_dtq, out_cerr, out_en)
        status[s] = st
