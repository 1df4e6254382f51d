"""Generalized-α, index 3 (Arnold & Brüls 2007): one sample at a time, over
the samples ``start:stop`` (threads run blocks of samples).

Built on the per-sample kernels of ``joints.py``, ``forces.py`` and ``linalg.py``. Rules every
kernel keeps: no reduction across samples (sample i's history is bit-identical alone, in any
chunk, on any thread count), never raise — failures set status bits with the time they
happened, and the sample's outputs from then on are NaN.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from mcchain.kernels.config import JIT
from mcchain.kernels.forces import (
    applied_forces,
    applied_stiffness_add,
    damper_stiffness_add,
    kinetic_energy,
    mass_diagonal,
    potential_energy,
    spring_vectors,
)
from mcchain.kernels.joints import (
    add_pair_outer,
    constraint_gamma,
    constraint_hessian_add,
    constraint_jacobian,
    constraint_residual,
    joint_forces,
)
from mcchain.kernels.linalg import lu_factor, lu_solve
from mcchain.model import JOINT_CLEARANCE
from mcchain.status import CONTACT_LOST, DIVERGED, FAILURE_BITS, SINGULAR


@njit(**JIT)
def generalized_alpha_run(
    start, stop, km, Q0, V0, t0, h, nstep, out_every, ncon, alpha_m, alpha_f, gam, beta, ctol, tau,
    max_newton, out_q, out_v, out_jf, out_cf, out_dtq, out_cerr, out_en,
    status, t_div, t_sing, t_cl, nsteps_out, nevals_out,
):  # fmt: skip
    """Generalized-α on M q̈ + Bᵀλ = F, Φ(q, t) = 0 for samples ``start:stop``.

    Each step: predict q̈_{n+1} = q̈_n, λ_{n+1} = λ_n, then Newton on the residuals
    (M q̈ + Bᵀλ − F, Φ) with the iteration matrix [[β′M + γ′C + K, Bᵀ], [B, 0]] (exact K
    from the joints' second derivatives and the load stiffness), constraint rows and λ
    scaled by β′ (Arnold & Brüls §3.3). LU with partial pivoting; a pivot ≤ ``tau`` × the
    largest entry flags SINGULAR, no convergence in ``max_newton`` iterations DIVERGED.
    Per sample: the steps completed (``nsteps_out``) and the residual evaluations, one for
    the start's index-1 solve and one per Newton iteration (``nevals_out``).
    """
    ndof = Q0.shape[1]
    nsys = ndof + ncon
    bp = (1.0 - alpha_m) / (beta * h * h * (1.0 - alpha_f))
    gp = gam / (beta * h)
    for s in range(start, stop):
        if status[s] & FAILURE_BITS:
            _nan_history(s, 0, out_q, out_v, out_jf, out_cf, out_dtq, out_cerr, out_en)
            continue
        q = Q0[s].copy()
        v = V0[s].copy()
        m = np.zeros(ndof)
        F = np.zeros(ndof)
        qdd = np.zeros(ndof)
        acc = np.zeros(ndof)
        qdd_old = np.zeros(ndof)
        lam = np.zeros(max(ncon, 1))
        phi = np.zeros(max(ncon, 1))
        B = np.zeros((max(ncon, 1), ndof))
        Kmat = np.zeros((nsys, nsys))
        rhs = np.zeros(nsys)
        piv = np.zeros(nsys, np.int64)
        jf = np.zeros((km.joint_body_a.shape[0], 2))
        cf = np.zeros(km.joint_body_a.shape[0])
        mass_diagonal(km, s, m)
        st = status[s]
        # Consistent start: q̈_0, λ_0 from the index-1 KKT system (γ from the joints).
        gamma = np.zeros(max(ncon, 1))
        _index1(km, s, q, v, t0, m, F, B, gamma, Kmat, rhs, piv, ndof, ncon)
        for i in range(ndof):
            qdd[i] = rhs[i]
            acc[i] = rhs[i]
        for r in range(ncon):
            lam[r] = rhs[ndof + r]
        written = 0  # output times written so far; after a failure the rest are NaN
        nst = 0
        nev = 1  # the start's index-1 solve
        for n in range(nstep + 1):
            t = t0 + n * h
            constraint_residual(km, s, q, t, phi)
            err = 0.0
            for r in range(ncon):
                err = max(err, abs(phi[r]))
            for i in range(ndof):
                err += 0.0 * (q[i] + v[i])
            if not (err <= ctol):
                st |= DIVERGED
                t_div[s] = t
                break
            for k in range(km.joint_body_a.shape[0]):
                clearance = km.joint_kind[k] == JOINT_CLEARANCE
                if clearance and lam[km.joint_row[k]] <= 0.0 and not st & CONTACT_LOST:
                    st |= CONTACT_LOST
                    t_cl[s] = t
            if n % out_every == 0:
                it = n // out_every
                joint_forces(km, s, q, lam, jf, cf)
                for i in range(ndof):
                    out_q[s, it, i] = q[i]
                    out_v[s, it, i] = v[i]
                for k in range(jf.shape[0]):
                    out_jf[s, it, 2 * k] = jf[k, 0]
                    out_jf[s, it, 2 * k + 1] = jf[k, 1]
                    out_cf[s, it, k] = cf[k]
                for d in range(km.driver_row.shape[0]):
                    out_dtq[s, it, d] = -lam[km.driver_row[d]]
                out_cerr[s, it] = err
                out_en[s, it] = kinetic_energy(km, s, v) + potential_energy(km, s, q)
                written = it + 1
            if n == nstep:
                break
            # Predictor.
            tn = t + h
            for i in range(ndof):
                qdd_old[i] = qdd[i]
                anew = (qdd[i] - alpha_m * acc[i]) / (1.0 - alpha_m)
                q[i] += h * v[i] + h * h * ((0.5 - beta) * acc[i] + beta * anew)
                v[i] += h * ((1.0 - gam) * acc[i] + gam * anew)
                acc[i] = anew
            converged = False
            singular = False
            pivot = np.inf
            for _ in range(max_newton):
                nev += 1
                applied_forces(km, s, q, v, tn, F)
                constraint_residual(km, s, q, tn, phi)
                constraint_jacobian(km, s, q, B)
                for i in range(nsys):
                    rhs[i] = 0.0
                    for j in range(nsys):
                        Kmat[i, j] = 0.0
                for i in range(ndof):
                    res = m[i] * qdd[i] - F[i]
                    for r in range(ncon):
                        res += B[r, i] * lam[r]
                    rhs[i] = -res
                    Kmat[i, i] = bp * m[i]
                for r in range(ncon):
                    rhs[ndof + r] = -bp * phi[r]
                    for i in range(ndof):
                        Kmat[ndof + r, i] = bp * B[r, i]
                        Kmat[i, ndof + r] = bp * B[r, i]
                # K = ∂(Bᵀλ)/∂q − ∂F/∂q, C = −∂F/∂q̇ (dampers), into the top-left block.
                _tangent_add(km, s, q, v, tn, lam, gp, Kmat)
                scale = 0.0
                for i in range(nsys):
                    for j in range(nsys):
                        scale = max(scale, abs(Kmat[i, j]))
                if not lu_factor(Kmat, nsys, piv, tau):
                    singular = True
                    break
                pivot = np.inf
                for i in range(nsys):
                    pivot = min(pivot, abs(Kmat[i, i]) / scale)
                lu_solve(Kmat, nsys, piv, rhs)
                dmax = 0.0
                qmax = 0.0
                for i in range(ndof):
                    q[i] += rhs[i]
                    v[i] += gp * rhs[i]
                    qdd[i] += bp * rhs[i]
                    dmax = max(dmax, abs(rhs[i]))
                    qmax = max(qmax, abs(q[i]))
                for r in range(ncon):
                    lam[r] += bp * rhs[ndof + r]
                if dmax <= 1e-13 * (1.0 + qmax):
                    converged = True
                    break
            if not converged and pivot < math.sqrt(tau):
                # Newton failing beside a near-zero pivot: rank loss, not a blow-up.
                singular = True
            if singular:
                st |= SINGULAR
                t_sing[s] = tn
                break
            if not converged:
                st |= DIVERGED
                t_div[s] = tn
                break
            for i in range(ndof):
                acc[i] += (1.0 - alpha_f) / (1.0 - alpha_m) * qdd[i]
                acc[i] -= (1.0 - alpha_f) / (1.0 - alpha_m) * qdd_old[i]
            nst += 1
        _nan_history(s, written, out_q, out_v, out_jf, out_cf, out_dtq, out_cerr, out_en)
        status[s] = st
        nsteps_out[s] = nst
        nevals_out[s] = nev


@njit(**JIT)
def _nan_history(s, first, out_q, out_v, out_jf, out_cf, out_dtq, out_cerr, out_en):
    """Outputs of sample ``s`` from history index ``first`` on are NaN (after a failure)."""
    for it in range(first, out_q.shape[1]):
        out_q[s, it, :] = np.nan
        out_v[s, it, :] = np.nan
        out_jf[s, it, :] = np.nan
        out_cf[s, it, :] = np.nan
        out_dtq[s, it, :] = np.nan
        out_cerr[s, it] = np.nan
        out_en[s, it] = np.nan


@njit(**JIT)
def _tangent_add(km, s, q, v, t, lam, gp, K_out):
    """K_out[:ndof, :ndof] += ∂(Bᵀλ)/∂q − ∂F/∂q + γ′ C, all exact: the joints' second
    derivatives, the loads' and springs' stiffness, the dampers' position dependence at fixed
    q̇, and C = −∂F/∂q̇ (along the spring; isotropic for rest length 0)."""
    constraint_hessian_add(km, s, q, lam, K_out)
    applied_stiffness_add(km, s, q, t, K_out)
    damper_stiffness_add(km, s, q, v, K_out)
    for k in range(km.spring_body_a.shape[0]):
        a = km.spring_body_a[k]
        b = km.spring_body_b[k]
        damping = km.spring_damping[s % km.spring_damping.shape[0], k]
        if damping == 0.0:
            continue
        pax, pay, pbx, pby, ux, uy = spring_vectors(km, s, q, k)
        if km.spring_rest_length[s % km.spring_rest_length.shape[0], k] == 0.0:
            add_pair_outer(K_out, gp * damping, a, b, 1.0, 0.0, pax, pay, pbx, pby)
            add_pair_outer(K_out, gp * damping, a, b, 0.0, 1.0, pax, pay, pbx, pby)
        else:
            length = math.hypot(ux, uy)
            add_pair_outer(K_out, gp * damping, a, b, ux / length, uy / length, pax, pay, pbx, pby)


@njit(**JIT)
def _index1(km, s, q, v, t, m, F, B, gamma, Kmat, rhs, piv, ndof, ncon):
    """Solve [[M, Bᵀ], [B, 0]] [q̈; λ] = [F; γ] (dense, for a start state) into ``rhs``."""
    applied_forces(km, s, q, v, t, F)
    constraint_jacobian(km, s, q, B)
    constraint_gamma(km, s, q, v, t, gamma)
    nsys = ndof + ncon
    for i in range(nsys):
        rhs[i] = 0.0
        for j in range(nsys):
            Kmat[i, j] = 0.0
    for i in range(ndof):
        Kmat[i, i] = m[i]
        rhs[i] = F[i]
    for r in range(ncon):
        rhs[ndof + r] = gamma[r]
        for i in range(ndof):
            Kmat[ndof + r, i] = B[r, i]
            Kmat[i, ndof + r] = B[r, i]
    if lu_factor(Kmat, nsys, piv, 1e-14):
        lu_solve(Kmat, nsys, piv, rhs)
    else:
        for i in range(nsys):
            rhs[i] = np.nan
