"""Generalized-α, index 3 (Arnold & Brüls 2007): one sample at a time, over
the samples ``start:stop`` (threads run blocks of samples).

Built on the per-sample kernels of ``joints.py``, ``forces.py`` and ``linalg.py``, and on
``clearance.py`` for joints under the contact law (their row's equation λ_r = F_n(q, q̇) joins
the Newton system; onsets, the switch of model auto and its re-seats are kept between steps as
the explicit kernels keep them). Rules every kernel keeps: no reduction across samples (sample
i's history is bit-identical alone, in any chunk, on any thread count), never raise — failures
set status bits with the time they happened, and the sample's outputs from then on are NaN.
"""

from __future__ import annotations

import math

import numpy as np

from mcchain.codes import JOINT_CLEARANCE
from mcchain.contact import CONTACT_STEP_LIMIT
from mcchain.kernels.clearance import (
    DFR,
    FM,
    FN,
    KC,
    NCST,
    PDC,
    PRC,
    contact_forces,
    contact_joint_index,
    contact_joints,
    contact_start,
    contact_step,
    contact_switch,
    law_rows,
    record_stage0,
)
from mcchain.kernels.config import INLINE, JIT, hypot, njit
from mcchain.kernels.explicit import (
    any_marked,
    finish_contact,
    nan_history,
    reseat,
    step_time,
    write_outputs,
)
from mcchain.kernels.forces import (
    applied_forces,
    applied_stiffness_add,
    damper_stiffness_add,
    kinetic_energy,
    mass_diagonal,
    own_row,
    spring_vectors,
)
from mcchain.kernels.joints import (
    add_pair_outer,
    constraint_gamma,
    constraint_hessian_add,
    constraint_jacobian,
    constraint_residual,
)
from mcchain.kernels.linalg import lu_factor, lu_solve
from mcchain.kernels.outputs import feed_outputs, output_state, outputs_finish
from mcchain.kernels.peaks import peak_values, peaks_feed, peaks_finish, peaks_start
from mcchain.kernels.tableaux import PEAK_CLOCK, PEAK_WIDTH
from mcchain.status import (
    CONTACT_LOST,
    CONTACT_STEP_TOO_LARGE,
    DIVERGED,
    FAILURE_BITS,
    SINGULAR,
)


@njit(**JIT)
def generalized_alpha_run(
    start, stop, km, Q0, V0, t_out, h, h_last, nstep, out_every, ncon, cols, first, alpha_m,
    alpha_f, gam, beta, ctol, tau, max_newton, row0, out_q, out_v, out_jf, out_cf, out_dtq,
    out_cerr, out_en, out_ct, sum_ct, peaks_out, out_spec, out_data, out_values, status, t_div,
    t_sing, t_cl, nsteps_out, nevals_out,
):  # fmt: skip
    """Generalized-α on M q̈ + Bᵀλ = F, Φ(q, t) = 0 for samples ``start:stop``: ``nstep``
    steps of ``h``, the last one ``h_last`` long, step n starting at
    :func:`mcchain.kernels.explicit.step_time`; outputs at the times ``t_out`` (every
    ``out_every`` steps, and t_end = t_out[-1] after the last step), sample s in row
    s − ``row0`` of the float64 histories (see explicit.rk4_run).

    Each step: predict q̈_{n+1} = q̈_n, λ_{n+1} = λ_n, then Newton on the residuals
    (M q̈ + Bᵀλ − F, Φ) with the iteration matrix [[β′M + γ′C + K, Bᵀ], [B, 0]] (exact K
    from the joints' second derivatives and the load stiffness), constraint rows and λ
    scaled by β′ (Arnold & Brüls §3.3). LU with partial pivoting; a pivot ≤ ``tau`` × the
    largest entry flags SINGULAR, no convergence in ``max_newton`` iterations DIVERGED.
    Per sample: the steps completed (``nsteps_out``) and the residual evaluations, one for
    the start's index-1 solve and one per Newton iteration (``nevals_out``).

    A joint under the contact law (:mod:`mcchain.kernels.clearance`) has the row
    λ_r − F_n(q, q̇) = 0 instead of Φ_r = 0, linearised with ∂F_n/∂δ and ∂F_n/∂δ̇ along n
    (the turning of n is left out of that row's tangent: Newton converges to the same
    solution). At each step's start, as the explicit kernels: ω_c h past
    CONTACT_STEP_LIMIT flags CONTACT_STEP_TOO_LARGE (the impacts would be damped by the
    method, not by the law), then the switch of model auto, the located onsets and
    separations, and the re-seats. ``cols``, ``first``: the constraint pattern (re-seat
    projection); ``out_ct``, ``sum_ct``, ``peaks_out``: the contact outputs and the
    continuous peaks (see explicit.rk4_run), fed with λ at every step's start, as the
    ``[[output]]``s (``out_spec``, ``out_data`` into ``out_values``, see explicit.rk4_run)
    with the state's q̈.
    """
    ndof = Q0.shape[1]
    nsys = ndof + ncon
    nj = km.joint_body_a.shape[0]
    ncj = contact_joints(km)
    npk = peaks_out.shape[1]
    nout = out_spec.shape[0]
    for s in range(start, stop):
        if status[s] & FAILURE_BITS:
            nan_history(s - row0, 0, out_q, out_v, out_jf, out_cf, out_dtq, out_cerr, out_en)
            for k in range(npk):
                peaks_out[s, k] = np.nan
            for k in range(nout):
                out_values[s, k] = np.nan
            continue
        ot, oscratch = output_state(km, nout)
        q = Q0[s].copy()
        v = V0[s].copy()
        m = np.zeros(ndof)
        minv = np.zeros(ndof)
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
        jf = np.zeros((nj, 2))
        cf = np.zeros(nj)
        cst = np.zeros((ncj, NCST))
        row_law = np.zeros((max(ncon, 1), 3))
        S = np.zeros((ncon, ncon))  # re-seat scratch
        work = np.zeros((4, ncon))
        contact_start(km, s, cst)
        pk = np.zeros(PEAK_WIDTH * npk + PEAK_CLOCK)
        peaks_start(pk)
        values = np.zeros(npk)
        mass_diagonal(km, s, m)
        for i in range(ndof):
            minv[i] = 1.0 / m[i]
        st = status[s]
        # Consistent start: q̈_0, λ_0 from the index-1 KKT system (γ from the joints).
        gamma = np.zeros(max(ncon, 1))
        _index1(km, s, q, v, t_out[0], m, F, B, gamma, Kmat, rhs, piv, ndof, ncon, cst, row_law)
        for i in range(ndof):
            qdd[i] = rhs[i]
            acc[i] = rhs[i]
        for r in range(ncon):
            lam[r] = rhs[ndof + r]
        written = 0  # output times written so far; after a failure the rest are NaN
        nst = 0
        nev = 1  # the start's index-1 solve
        hb = h  # the step that ended at t (at the start: none, h)
        for n in range(nstep + 1):
            t = step_time(n, nstep, out_every, h, t_out)
            constraint_residual(km, s, q, t, phi)
            law_rows(km, cst, row_law)
            err = 0.0
            for r in range(ncon):
                if row_law[r, 0] != 1.0 and own_row(km, r):
                    err = max(err, abs(phi[r]))
            for i in range(ndof):
                err += 0.0 * (q[i] + v[i])
            if not (err <= ctol):
                st |= DIVERGED
                t_div[s] = t
                break
            for k in range(nj):
                clearance = km.joint_kind[k] == JOINT_CLEARANCE and km.joint_model[k] == 0
                if clearance and lam[km.joint_row[k]] <= 0.0 and not st & CONTACT_LOST:
                    st |= CONTACT_LOST
                    t_cl[s] = t
            if ncj > 0:
                if not _contact_bookkeeping(km, s, q, v, t, hb, lam, minv, B, F, cst, row_law):
                    st |= CONTACT_STEP_TOO_LARGE
                    break
                if any_marked(cst):
                    reseat(
                        km, s, q, v, t, minv, cols, first, cst, row_law, tau, B, S, work[0],
                        work[1], work[2], work[3],
                    )  # fmt: skip
            peak_values(km, lam, cst, values)
            peaks_feed(pk, values, t)
            if nout > 0:
                feed_outputs(km, s, ot, out_spec, out_data, t, q, v, qdd, lam, cst, oscratch)
            if n == nstep or n % out_every == 0:
                it = t_out.shape[0] - 1 if n == nstep else n // out_every
                write_outputs(
                    km, s, s - row0, it, q, v, lam, cst, jf, cf, err, out_q, out_v, out_jf,
                    out_cf, out_dtq, out_cerr, out_en, out_ct,
                )  # fmt: skip
                written = it + 1
            if n == nstep:
                break
            # Predictor.
            hn = h if n + 1 < nstep else h_last
            bp = (1.0 - alpha_m) / (beta * hn * hn * (1.0 - alpha_f))
            gp = gam / (beta * hn)
            tn = step_time(n + 1, nstep, out_every, h, t_out)
            hb = hn
            for i in range(ndof):
                qdd_old[i] = qdd[i]
                anew = (qdd[i] - alpha_m * acc[i]) / (1.0 - alpha_m)
                q[i] += hn * v[i] + hn * hn * ((0.5 - beta) * acc[i] + beta * anew)
                v[i] += hn * ((1.0 - gam) * acc[i] + gam * anew)
                acc[i] = anew
            converged = False
            singular = False
            pivot = np.inf
            for _ in range(max_newton):
                nev += 1
                applied_forces(km, s, q, v, tn, F)
                contact_forces(km, s, q, v, cst, F)
                law_rows(km, cst, row_law)
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
                _law_rows_newton(km, cst, row_law, lam, B, bp, gp, ndof, Kmat, rhs)
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
            if hn != h:
                # The last step, shortened to land on t_end: an index-3 step's multipliers
                # carry the drift of the velocity constraints divided by the step, which a
                # short step magnifies (0.7 % of a driver torque after a fifth of dt); the
                # landed state's q̈ and λ come from the index-1 equations, as the start's do.
                nev += 1
                _index1(km, s, q, v, tn, m, F, B, gamma, Kmat, rhs, piv, ndof, ncon, cst, row_law)
                for i in range(ndof):
                    qdd[i] = rhs[i]
                for r in range(ncon):
                    lam[r] = rhs[ndof + r]
        nan_history(s - row0, written, out_q, out_v, out_jf, out_cf, out_dtq, out_cerr, out_en)
        peaks_finish(s, (st & FAILURE_BITS) != 0, pk, npk, peaks_out)
        outputs_finish(s, (st & FAILURE_BITS) != 0, ot, out_spec, out_data, out_values)
        finish_contact(km, s, st, written, cst, out_ct, sum_ct, peaks_out)
        status[s] = st
        nsteps_out[s] = nst
        nevals_out[s] = nev


@njit(**INLINE)
def _contact_bookkeeping(km, s, q, v, t, h, lam, minv, B, F, cst, row_law):
    """At a step's start (q, v, t) with the multipliers ``lam``: δ, δ̇ and ω_c² of every
    contact-law joint, then the bookkeeping of the step that ended here
    (:func:`mcchain.kernels.clearance.contact_step`) and the switch of model auto. Returns
    False when ω_c h > CONTACT_STEP_LIMIT (``F``, ``B``: scratch)."""
    contact_forces(km, s, q, v, cst, F)
    constraint_jacobian(km, s, q, B)
    kinetic = kinetic_energy(km, s, v)
    largest = 0.0
    for j in range(cst.shape[0]):
        r = km.joint_row[contact_joint_index(km, j)]
        inverse_mass = 0.0
        for i in range(B.shape[1]):
            inverse_mass += B[r, i] * minv[i] * B[r, i]
        row_law[r, 2] = inverse_mass
        largest = max(largest, cst[j, KC] * inverse_mass)
    record_stage0(km, cst, row_law)
    if h * h * largest > CONTACT_STEP_LIMIT * CONTACT_STEP_LIMIT:
        return False
    for j in range(cst.shape[0]):
        lam_r = lam[km.joint_row[contact_joint_index(km, j)]]
        contact_step(km, s, cst, j, lam_r, t, h, cst[j, PDC], cst[j, PRC], kinetic)
        contact_switch(km, cst, j, lam_r, t, cst[j, PDC])  # after: h was on the link
    return True


@njit(**INLINE)
def _law_rows_newton(km, cst, row_law, lam, B, bp, gp, ndof, Kmat, rhs):
    """Rows of joints under the contact law in the Newton system: λ_r + β′x_r − F_n(q, q̇) = 0
    with Δλ_r = β′x_r, linearised as −(∂F_n/∂δ + γ′ ∂F_n/∂δ̇) B_r Δq + β′ x_r = F_n − λ_r
    (δ̇ = B_r q̇ and Δq̇ = γ′Δq; the columns Bᵀ of the momentum rows stay: −F_n n on the
    journal)."""
    for j in range(cst.shape[0]):
        if cst[j, FM] != 1.0:
            continue
        r = km.joint_row[contact_joint_index(km, j)]
        slope = cst[j, KC] + gp * cst[j, DFR]
        for i in range(ndof):
            Kmat[ndof + r, i] = -slope * B[r, i]
        Kmat[ndof + r, ndof + r] = bp
        rhs[ndof + r] = cst[j, FN] - lam[r]


@njit(**INLINE)
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
            length = hypot(ux, uy)
            add_pair_outer(K_out, gp * damping, a, b, ux / length, uy / length, pax, pay, pbx, pby)


@njit(**INLINE)
def _index1(km, s, q, v, t, m, F, B, gamma, Kmat, rhs, piv, ndof, ncon, cst, row_law):
    """Solve [[M, Bᵀ], [B, 0]] [q̈; λ] = [F; γ] (dense, for a start state) into ``rhs``; a
    row under the contact law is λ_r = F_n."""
    applied_forces(km, s, q, v, t, F)
    contact_forces(km, s, q, v, cst, F)
    law_rows(km, cst, row_law)
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
        if row_law[r, 0] == 1.0:
            for i in range(ndof):
                Kmat[ndof + r, i] = 0.0
            Kmat[ndof + r, ndof + r] = 1.0
            rhs[ndof + r] = row_law[r, 1]
    if lu_factor(Kmat, nsys, piv, 1e-14):
        lu_solve(Kmat, nsys, piv, rhs)
    else:
        for i in range(nsys):
            rhs[i] = np.nan
