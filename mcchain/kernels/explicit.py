"""Explicit Runge–Kutta on the generic kernels: the loop path, one sample at a time.

The generated lane kernels (:mod:`mcchain.codegen`) are straight-line code per topology:
fastest per step, but every new topology compiles a new module. This module integrates
any topology with the per-sample kernels of ``joints.py``, ``forces.py`` and ``linalg.py``
(the Schur complement S = B M⁻¹ Bᵀ formed over B's non-zeros and factored in its envelope),
so it compiles once per installation. It follows the lanes' fixed-step RK4 step by step
(``[simulate] kernels = "loop"``): the same stages, the same failure checks at each step's
start (max |Φ| past the tolerance: DIVERGED; rank loss in a stage: SINGULAR at the step's
end; λ ≤ 0 at a link clearance joint: CONTACT_LOST), the same contact law, switches and
re-seats (:mod:`mcchain.kernels.clearance`) and the same outputs from the first stage's λ.
Rules every kernel keeps: no reduction across samples, never raise, NaN from a failure on.
"""

from __future__ import annotations

import math

import numpy as np

from mcchain.codes import JOINT_CLEARANCE
from mcchain.contact import CONTACT_STEP_LIMIT, RESEAT_NEWTON, RESEAT_TOLERANCE
from mcchain.kernels.assembly import max_abs
from mcchain.kernels.clearance import (
    DWL,
    FM,
    NCST,
    PDC,
    PKF,
    PRC,
    SUMMARY_COLUMNS,
    VI,
    contact_forces,
    contact_joint_index,
    contact_joints,
    contact_pulsation,
    contact_start,
    contact_step,
    contact_switch,
    law_rows,
    record_stage0,
)
from mcchain.kernels.config import INLINE, JIT, hypot, njit
from mcchain.kernels.contact import contact_mode, elastic_energy
from mcchain.kernels.forces import (
    applied_forces,
    kinetic_energy,
    mass_diagonal,
    own_items,
    own_row,
    potential_energy,
)
from mcchain.kernels.joints import (
    constraint_gamma,
    constraint_jacobian,
    constraint_residual,
    constraint_velocity_rhs,
    joint_forces,
    joint_vectors,
)
from mcchain.kernels.outputs import feed_outputs, output_state, outputs_finish
from mcchain.kernels.peaks import (
    PEAK_CLOCK,
    PEAK_WIDTH,
    peak_values,
    peaks_feed,
    peaks_finish,
    peaks_start,
)
from mcchain.status import (
    CONTACT_LOST,
    CONTACT_STEP_TOO_LARGE,
    DIVERGED,
    FAILURE_BITS,
    SINGULAR,
)


@njit(**JIT)
def nan_history(s, first, out_q, out_v, out_jf, out_cf, out_dtq, out_cerr, out_en):
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
def finish_contact(km, s, st, written, cst, out_ct, sum_ct, peaks_out):
    """A sample's contact outputs after its run: δ and the mode NaN from history index
    ``written`` on; the summaries per joint, NaN after a failure. The peak contact force is
    the joint's continuous peak of |joint force| (``peaks_out[s]``, filled before)."""
    for it in range(written, out_ct.shape[1]):
        out_ct[s, it, :] = np.nan
    for j in range(cst.shape[0]):
        cst[j, PKF] = peaks_out[s, contact_joint_index(km, j)]
        for c in range(len(SUMMARY_COLUMNS)):
            value = cst[j, SUMMARY_COLUMNS[c]]
            sum_ct[s, len(SUMMARY_COLUMNS) * j + c] = np.nan if st & FAILURE_BITS else value


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
def constraint_rates(B, cols, v, nu, m, out):
    """Φ̇_r = B_r q̇ − ν_r of the m rows into ``out``, over each row's non-zeros (``cols``,
    see :func:`index1_acceleration`); ``out`` may be ``nu`` itself."""
    for r in range(m):
        rate = -nu[r]
        for c in range(cols.shape[1]):
            k = cols[r, c]
            if k < 0:
                break
            rate += B[r, k] * v[k]
        out[r] = rate


@njit(**JIT)
def schur_matrix(B, minv, cols, first, m, S_out):
    """S = B M⁻¹ Bᵀ (m rows) into ``S_out`` over B's non-zeros, in the envelope ``first``
    (both triangles written; entries outside the envelope are never read)."""
    width = cols.shape[1]
    for i in range(m):
        for j in range(first[i], i + 1):
            acc = 0.0
            for c in range(width):
                k = cols[i, c]
                if k < 0:
                    break
                acc += B[i, k] * minv[k] * B[j, k]
            S_out[i, j] = acc
            S_out[j, i] = acc


@njit(**JIT)
def replace_law_rows(S, m, first, row_law, rhs):
    """Rows under the contact law (``row_law[r, 0]`` = 1) become λ_r = F_n
    (``row_law[r, 1]``): S's row and column r the unit vector (the factors keep their
    envelope), ``rhs[r]`` = F_n and the coupling S_ir F_n moved to the other rows' right-hand
    sides. ``row_law[:, 2]`` receives S's diagonal before the replacement (1/m* of a law
    row, for the step-size check)."""
    for r in range(m):
        row_law[r, 2] = S[r, r]
    for r in range(m):
        if row_law[r, 0] != 1.0:
            continue
        fn = row_law[r, 1]
        for i in range(m):
            if i == r or not (first[i] <= r if i > r else first[r] <= i):
                continue
            if row_law[i, 0] != 1.0:
                rhs[i] -= fn * S[i, r]
            S[i, r] = 0.0
            S[r, i] = 0.0
        S[r, r] = 1.0
        rhs[r] = fn


@njit(**INLINE)
def index1_acceleration(km, s, q, v, t, balpha2, bbeta2, tau, minv, cols, first, cst, row_law,
                        work_B, work_S, work_F, work_g, work_phi, qdd_out, lam_out):  # fmt: skip
    """q̈ and λ of M q̈ + Bᵀλ = F, B q̈ = γ − 2α Φ̇ − β² Φ at (q, v, t) for one sample.

    ``minv`` (ndof,) is M⁻¹; ``cols`` (ncon, 6) the columns where each row of B may be
    non-zero (−1 after the last) and ``first`` (ncon,) the envelope of S
    (:meth:`mcchain.model.Model.constraint_pattern`): every product below runs over the
    non-zeros only, so a step costs O(ncon · band²), not O(ncon² ndof). ``cst`` (ncj, NCST)
    the contact-law joints' state (:mod:`mcchain.kernels.clearance`; empty without them):
    their δ, δ̇, F_n are evaluated here, friction joins F, and the row of a joint under the
    law becomes λ_r = F_n (``row_law`` (ncon, 3) scratch, see :func:`replace_law_rows`).
    ``work_*`` are scratch of shapes (ncon, ndof), (ncon, ncon), (ndof,), (ncon,), (ncon,).
    λ = S⁻¹ (B M⁻¹ F − γ′), q̈ = M⁻¹ (F − Bᵀλ); the sums skip exact zeros only, so the values
    are those of the dense products.

    Returns:
        max |Φ| at (q, t) over the rows not under the law, or −1 − max |Φ| when S lost rank
        (a pivot ≤ ``tau`` × its diagonal entry: that row's λ is 0, the basic solution, as
        the lanes' LDLᵀ).
    """
    n = q.shape[0]
    m = lam_out.shape[0]
    width = cols.shape[1]
    applied_forces(km, s, q, v, t, work_F)
    contact_forces(km, s, q, v, cst, work_F)
    law_rows(km, cst, row_law)
    constraint_residual(km, s, q, t, work_phi)
    for r in range(m):
        if row_law[r, 0] == 1.0:
            work_phi[r] = 0.0
    err = max_abs(work_phi, m)
    if km.reference.shape[0] > 0:  # an ideal copy's rows are not the mechanism's
        err = 0.0
        for r in range(m):
            if own_row(km, r) and not abs(work_phi[r]) <= err:
                err = abs(work_phi[r])
    for k in range(n):
        qdd_out[k] = work_F[k]
    if m > 0:
        constraint_jacobian(km, s, q, work_B)
        constraint_gamma(km, s, q, v, t, work_g)
        constraint_velocity_rhs(km, s, t, lam_out)  # ν, then Φ̇ = B q̇ − ν (drivers: −Φ_t)
        constraint_rates(work_B, cols, v, lam_out, m, lam_out)
        for r in range(m):
            work_g[r] -= balpha2 * lam_out[r] + bbeta2 * work_phi[r]
        schur_matrix(work_B, minv, cols, first, m, work_S)
        for r in range(m):
            acc = -work_g[r]
            for c in range(width):
                k = cols[r, c]
                if k < 0:
                    break
                acc += work_B[r, k] * minv[k] * work_F[k]
            lam_out[r] = acc
        replace_law_rows(work_S, m, first, row_law, lam_out)
        dropped = ldl_factor(work_S, m, first, tau, work_phi)
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


@njit(**INLINE)
def project_onto_link(km, s, q, v, t, minv, cols, first, cst, row_law, ptol, max_newton, tau,
                      work_B, work_S, work_phi, work_rate, work_nu, work_dinv):  # fmt: skip
    """Project q onto Φ(q, t) = 0 (Gauss–Newton in the M metric: dq = −M⁻¹Bᵀ S⁻¹ Φ; stops at
    ``ptol``, on stagnation or after ``max_newton`` steps), then v onto Φ̇ = 0 at the
    projected q, as the lanes' projection does; the rows of joints still under the law are
    left free (``row_law``)."""
    m = work_phi.shape[0]
    width = cols.shape[1]
    law_rows(km, cst, row_law)
    for r in range(m):
        row_law[r, 1] = 0.0  # a row under the law gets no correction
    pmax = math.inf
    for itn in range(max_newton + 1):
        constraint_residual(km, s, q, t, work_phi)
        constraint_jacobian(km, s, q, work_B)
        constraint_velocity_rhs(km, s, t, work_nu)
        constraint_rates(work_B, cols, v, work_nu, m, work_rate)
        phimax = 0.0
        for r in range(m):
            if row_law[r, 0] == 1.0:
                work_phi[r] = 0.0
                work_rate[r] = 0.0
            phimax = max(phimax, abs(work_phi[r]))
        converged = phimax <= ptol or itn == max_newton or phimax >= 0.5 * pmax
        converged = converged or phimax != phimax
        pmax = phimax
        schur_matrix(work_B, minv, cols, first, m, work_S)
        replace_law_rows(work_S, m, first, row_law, work_rate if converged else work_phi)
        ldl_factor(work_S, m, first, tau, work_dinv)
        x = work_rate if converged else work_phi
        ldl_solve(work_S, m, first, work_dinv, x)
        y = v if converged else q
        for r in range(m):
            for c in range(width):
                k = cols[r, c]
                if k < 0:
                    break
                y[k] -= minv[k] * work_B[r, k] * x[r]
        if converged:
            return


@njit(**JIT)
def contact_energy(km, s, q, cst):
    """Elastic energy K δ^(m+1)/(m+1) stored in the contacts of the joints under the law, J."""
    energy = 0.0
    for j in range(cst.shape[0]):
        if cst[j, FM] != 1.0:
            continue
        k = contact_joint_index(km, j)
        _, _, _, _, dx, dy = joint_vectors(km, s, q, k)
        pen = hypot(dx, dy) - km.joint_clearance[s % km.joint_clearance.shape[0], k]
        stiffness = km.joint_contact_stiffness[s % km.joint_contact_stiffness.shape[0], k]
        expo = km.joint_contact_exponent[s % km.joint_contact_exponent.shape[0], k]
        energy += elastic_energy(pen, stiffness, expo)
    return energy


@njit(**JIT)
def reseat(km, s, q, v, t, minv, cols, first, cst, row_law, tau, work_B, work_S, work_phi,
           work_rate, work_nu, work_dinv):  # fmt: skip
    """The joints marked for re-seating (DWL < 0) go back to the link: q and v projected onto
    it (M-orthogonal: the velocity step cannot add kinetic energy); without drivers the
    position step's excess energy (up to m/(m+1) F_n δ beyond the elastic energy it drops) is
    taken from the kinetic energy, so a re-seat never adds energy (docs/contact.md)."""
    before = kinetic_energy(km, s, v) + potential_energy(km, s, q) + contact_energy(km, s, q, cst)
    for j in range(cst.shape[0]):
        if cst[j, DWL] < 0.0:
            cst[j, FM] = 0.0
            cst[j, DWL] = 0.0
    project_onto_link(
        km, s, q, v, t, minv, cols, first, cst, row_law, RESEAT_TOLERANCE, RESEAT_NEWTON, tau,
        work_B, work_S, work_phi, work_rate, work_nu, work_dinv,
    )  # fmt: skip
    if km.driver_row.shape[0] > 0:
        return
    kinetic = kinetic_energy(km, s, v)
    excess = kinetic + potential_energy(km, s, q) + contact_energy(km, s, q, cst) - before
    if excess > 0.0 and kinetic > excess:
        scale = math.sqrt((kinetic - excess) / kinetic)
        for i in range(3 * own_items(km, 0, v.shape[0] // 3)):  # not an ideal copy's
            v[i] = scale * v[i]


@njit(**JIT)
def rk4_run(
    start, stop, km, Q0, V0, t_out, h, h_last, nstep, out_every, ncon, cols, first, A, bw, cc,
    balpha2, bbeta2, ctol, tau, row0, out_q, out_v, out_jf, out_cf, out_dtq, out_cerr, out_en,
    out_ct, sum_ct, peaks_out, out_spec, out_data, out_values, status, t_div, t_sing, t_cl,
):  # fmt: skip
    """Fixed-step RK4 (tableau ``A``, ``bw``, ``cc``, strictly sub-diagonal) with Baumgarte
    on the samples ``start:stop``: ``nstep`` steps of ``h``, the last one ``h_last`` long;
    step n starts at :func:`step_time`, and the outputs are written at the times ``t_out``
    (every ``out_every`` steps, and t_end = t_out[-1] after the last step). ``cols``,
    ``first``: the constraint pattern (:func:`index1_acceleration`). The histories
    ``out_q`` .. ``out_en`` (float64) hold the samples from ``row0`` on: sample s in row
    s − row0 (the caller may pass a block's rows and store them as float32: the kernel
    compiles for one type of histories).

    Contact-law joints (:mod:`mcchain.kernels.clearance`), as the lanes: after each step's
    first stage, the step-size check (ω_c h > CONTACT_STEP_LIMIT: CONTACT_STEP_TOO_LARGE),
    the switch of model auto at λ ≤ 0 and the bookkeeping of the step that ended there;
    after the step, the re-seats. ``out_ct`` (nsample, ntime, 2 ncj): δ and the mode
    (0 link, 1 contact, 2 free) per output time; ``sum_ct`` (nsample, 5 ncj): the summaries
    (mcchain.contact.CONTACT_SUMMARY) per joint, their peak contact force the continuous one.
    ``peaks_out`` (nsample, njoint + ndriver): the continuous peaks of |joint force| and
    |driver torque| (:mod:`mcchain.kernels.peaks`), fed at every step's start; the
    ``[[output]]``s (``out_spec``, ``out_data``: :func:`mcchain.kernels.outputs.outputs_feed`)
    into ``out_values`` (nsample, nout), fed there too.
    """
    ndof = Q0.shape[1]
    nj = km.joint_body_a.shape[0]
    nstage = bw.shape[0]
    ncj = contact_joints(km)
    limit2 = CONTACT_STEP_LIMIT * CONTACT_STEP_LIMIT
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
        minv = np.zeros(ndof)
        mass_diagonal(km, s, minv)
        for i in range(ndof):
            minv[i] = 1.0 / minv[i]
        B = np.zeros((ncon, ndof))
        S = np.zeros((ncon, ncon))
        F = np.zeros(ndof)
        g = np.zeros(ncon)
        phi = np.zeros(ncon)
        nu = np.zeros(ncon)
        dinv = np.zeros(ncon)
        lam = np.zeros(ncon)
        lam0 = np.zeros(ncon)
        row_law = np.zeros((ncon, 3))
        cst = np.zeros((ncj, NCST))
        contact_start(km, s, cst)
        pk = np.zeros(PEAK_WIDTH * npk + PEAK_CLOCK)
        peaks_start(pk)
        values = np.zeros(npk)
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
        wca = 0.0  # largest ω_c² since the last check
        written = 0
        hb = h  # the step that ended at t (at the start: none, h)
        for n in range(nstep + 1):
            t = step_time(n, nstep, out_every, h, t_out)
            hn = h if n + 1 < nstep else h_last
            singular = pending
            pending = False
            err0 = 0.0
            for stage in range(nstage if n < nstep else 1):
                ts = t + cc[stage] * hn
                ah = A[stage, stage - 1] * hn if stage > 0 else 0.0
                bh = bw[stage] * hn
                for i in range(ndof):
                    qs[i] = q[i] + ah * kq[i] if stage > 0 else q[i]
                    vs[i] = v[i] + ah * kv[i] if stage > 0 else v[i]
                err = index1_acceleration(
                    km, s, qs, vs, ts, balpha2, bbeta2, tau, minv, cols, first, cst, row_law, B,
                    S, F, g, phi, qdd, lam,
                )  # fmt: skip
                if err < 0.0:
                    err = -err - 1.0
                    if stage == 0:
                        singular = True
                    else:
                        pending = True  # flagged at the step's end, as the lanes do
                wca = max(wca, contact_pulsation(km, cst, row_law))
                for i in range(ndof):
                    kq[i] = vs[i]
                    kv[i] = qdd[i]
                    dq[i] = (dq[i] if stage > 0 else 0.0) + bh * kq[i]
                    dv[i] = (dv[i] if stage > 0 else 0.0) + bh * kv[i]
                if stage > 0:
                    continue
                err0 = err
                for r in range(ncon):
                    lam0[r] = lam[r]
                record_stage0(km, cst, row_law)
                # Failures, once per step at its start (a singular later stage: at the
                # step's end); then contact loss of link joints and the contact-law joints.
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
                        link = km.joint_model[k] == 0
                        if link and km.joint_kind[k] == JOINT_CLEARANCE:
                            if lam0[km.joint_row[k]] <= 0.0:
                                st |= CONTACT_LOST
                                t_cl[s] = t
                                break
                if ncj > 0:
                    if hb * hb * wca > limit2:
                        st |= CONTACT_STEP_TOO_LARGE
                        break
                    kinetic = kinetic_energy(km, s, v)
                    for j in range(ncj):
                        lam_r = lam0[km.joint_row[contact_joint_index(km, j)]]
                        d1, r1 = cst[j, PDC], cst[j, PRC]
                        contact_step(km, s, cst, j, lam_r, t, hb, d1, r1, kinetic)
                        contact_switch(km, cst, j, lam_r, t, d1)  # after: hb was on the link
                    wca = 0.0
                peak_values(km, lam0, cst, values)
                peaks_feed(pk, values, t)
                if nout > 0:
                    feed_outputs(km, s, ot, out_spec, out_data, t, q, v, qdd, lam0, cst, oscratch)
                if n == nstep or n % out_every == 0:
                    it = t_out.shape[0] - 1 if n == nstep else n // out_every
                    write_outputs(
                        km, s, s - row0, it, q, v, lam0, cst, jf, cf, err0, out_q, out_v,
                        out_jf, out_cf, out_dtq, out_cerr, out_en, out_ct,
                    )  # fmt: skip
                    written = it + 1
            if st & FAILURE_BITS or n == nstep:
                break
            for i in range(ndof):
                q[i] += dq[i]
                v[i] += dv[i]
            hb = hn
            if any_marked(cst):
                tn = step_time(n + 1, nstep, out_every, h, t_out)
                reseat(
                    km, s, q, v, tn, minv, cols, first, cst, row_law, tau, B, S, phi, g, nu, dinv,
                )  # fmt: skip
        nan_history(s - row0, written, out_q, out_v, out_jf, out_cf, out_dtq, out_cerr, out_en)
        peaks_finish(s, (st & FAILURE_BITS) != 0, pk, npk, peaks_out)
        outputs_finish(s, (st & FAILURE_BITS) != 0, ot, out_spec, out_data, out_values)
        finish_contact(km, s, st, written, cst, out_ct, sum_ct, peaks_out)
        status[s] = st


@njit(**INLINE)
def step_time(n, nstep, out_every, h, t_out):
    """Time of step ``n`` of ``nstep`` (s): t_out[n // out_every] + (n % out_every) h, and
    t_end = t_out[-1] for n = ``nstep``; from n, never accumulated (see
    :class:`mcchain.solvers.grid.OutputGrid`, which the lanes' loop follows too)."""
    if n == nstep:
        return t_out[t_out.shape[0] - 1]
    return t_out[n // out_every] + (n % out_every) * h


@njit(**JIT)
def any_marked(cst):
    """Whether a contact-law joint was marked for re-seating (DWL < 0) in the last step."""
    for j in range(cst.shape[0]):
        if cst[j, DWL] < 0.0:
            return True
    return False


@njit(**JIT)
def write_outputs(km, s, row, it, q, v, lam, cst, jf, cf, err, out_q, out_v, out_jf, out_cf,
                  out_dtq, out_cerr, out_en, out_ct):  # fmt: skip
    """The outputs of sample ``s`` at history index ``it``, into row ``row`` of ``out_q`` ..
    ``out_en`` and row ``s`` of the contact history ``out_ct``: the state, the reactions from λ
    (a joint under the law: F_n ≥ 0, clipped at its switch from the link), the driver
    torques, max |Φ|, the energy (with the contacts' elastic energy), δ and each contact-law
    joint's mode. Nothing where the histories hold no time (``[storage] histories =
    "none"``: arrays of 0 times)."""
    if it >= out_q.shape[1]:
        return
    ndof = q.shape[0]
    joint_forces(km, s, q, lam, jf, cf)
    for j in range(cst.shape[0]):
        k = contact_joint_index(km, j)
        if cst[j, FM] == 1.0 and cf[k] < 0.0:
            jf[k, 0] = 0.0 * jf[k, 0]
            jf[k, 1] = 0.0 * jf[k, 1]
            cf[k] = 0.0
        pen = cst[j, PDC]
        out_ct[s, it, 2 * j] = pen
        out_ct[s, it, 2 * j + 1] = contact_mode(cst[j, FM], pen, cst[j, VI])
    for i in range(ndof):
        out_q[row, it, i] = q[i]
        out_v[row, it, i] = v[i]
    for k in range(jf.shape[0]):
        out_jf[row, it, 2 * k] = jf[k, 0]
        out_jf[row, it, 2 * k + 1] = jf[k, 1]
        out_cf[row, it, k] = cf[k]
    for d in range(km.driver_row.shape[0]):
        out_dtq[row, it, d] = -lam[km.driver_row[d]]
    out_cerr[row, it] = err
    energy = kinetic_energy(km, s, v) + potential_energy(km, s, q)
    out_en[row, it] = energy + contact_energy(km, s, q, cst)
