"""The adaptive (rk45) lane kernel's templates, in the notation of
:mod:`mcchain.codegen.templates` (``@[row]``, ``@@block``, ``SUFFIX`` and the other tokens of
:func:`mcchain.codegen.generate.generate_source`): the entry ``adaptive_run``, its stages,
its outputs on an accepted state, and its dense output points."""

from __future__ import annotations

from mcchain.codegen.templates import LANE_FINISH, LANE_SETUP, WORK_ARRAYS, lanes_block

ADAPTIVE_ARGS = """P, Q0, V0, t0, t_out, h0, A, bw, be, cc, dense, order_err, rtol, atol, hmin,
                 max_steps, balpha2, bbeta2, ctol, tau, lanes,
                 out_q, out_v, out_jf, out_cf, out_dtq, out_cerr, out_en@CT, out_pk@OT,
                 status, t_div, t_sing, t_cl, nsteps_out, nrejected_out, nevals_out, queue"""

ADAPTIVE_LANE_START = """
@[smp] = sl
@[fsm] = 1.0
@[tl] = t0
iout[l] = 0
nstp[l] = 0
nrej[l] = 0
hl[l] = h0
run[l] = True
nev[l] = 0 if (st[l] & FAILBITS) != 0 else 1
"""
"""... and, in the adaptive kernel, its clocks: the first stage (FSAL) is still to compute
(row ``fsm``)."""

ADAPTIVE_KERNEL = (
    f'''
@njit(**JIT)
def adaptive_run(g_start, g_stop, {ADAPTIVE_ARGS}):
    """Embedded Runge–Kutta (NSTAGE stages, FSAL) with per-sample step control, on the
    samples of lane groups g_start:g_stop (``lanes`` samples each), taken one at a time from
    the queue ``queue[0]`` (an int64 array: the next sample; the caller sets it to
    g_start · lanes). Threads that run this call on the same samples share the queue
    (``take_next`` gives each sample to one lane of one thread): none waits for another's
    slower samples, and every lane drains once, at the end.

    Every lane has its own time and step, which the output times do not cut: the last step
    lands on t_end exactly, and an output time inside an accepted step takes the step's
    continuous extension (``dense``: Tableau.dense) and one evaluation there
    (group_dense). A lane whose step would fall below ``hmin`` or that exceeds
    ``max_steps`` attempts is flagged DIVERGED. Per sample: accepted steps, rejected steps
    and stage evaluations (the first stage, then NSTAGE - 1 per attempt: FSAL) into
    ``nsteps_out``, ``nrejected_out``, ``nevals_out``.

    A lane whose sample is finished takes the queue's next sample (row ``smp``), so the
    lanes do not wait for the slowest sample of a group: samples take their own numbers
    of steps. A sample's numbers do not depend on the lane or thread it runs in or beside
    whom.
    """
    nsample = Q0.shape[1]
    nout = t_out.shape[0]
    expo = -1.0 / (order_err + 1.0)
    # below this error norm the ratio is MAX_FACTOR without the power (tableaux.CAP_MARGIN)
    en_cap = (MAX_FACTOR / SAFETY * CAP_MARGIN) ** -(order_err + 1.0)
    lanes = max(1, min(lanes, LMAXV))
    stop = min(g_stop * lanes, nsample)
    first = np.zeros(LMAXV, np.int64)
    nl = 0
    for l in range(lanes):
        sl = take_next(queue)
        if sl >= stop:
            break
        first[l] = sl
        nl += 1
    if nl <= 0:
        return'''
    + WORK_ARRAYS.replace("\n        ", "\n    ")
    + """
    iout = np.zeros(LMAXV, np.int64)
    nstp = np.zeros(LMAXV, np.int64)
    nrej = np.zeros(LMAXV, np.int64)
    nev = np.zeros(LMAXV, np.int64)
    run = np.zeros(LMAXV, np.bool_)
    hl = np.zeros(LMAXV)
    for l in range(nl):
        sl = first[l]
"""
    + lanes_block(LANE_SETUP, 8)
    + "\n"
    + lanes_block(ADAPTIVE_LANE_START, 8)
    + """
    nfresh = nl
    while True:
        if nfresh > 0:
            # First stage at the fresh lanes' start; later steps reuse the last stage (FSAL).
            group_first_stage_SUFFIX(W, nl, A, balpha2, bbeta2, tau)
            for l in range(nl):
                if @[fsm] > 0.0:
                    @@contact_start
                    @[fsm] = 0.0
        nfresh = 0
        # Failures, contact and outputs at each lane's current (accepted) state (a lane's
        # state met again after a rejected step, or beside fresh lanes, changes nothing);
        # the outputs of the lanes on an output time (row lnd) all at once, after.
        nrun = 0
        nland = 0
        ndone = 0
        for l in range(nl):
            @[lnd] = 0.0
            if not run[l]:
                continue
            alive = (st[l] & FAILBITS) == 0
            if alive and not (@[chk] <= ctol):
                st[l] |= DIVERGED_BIT
                tdv[l] = @[tl]
                alive = False
            if alive and @[sg] > 0.0:
                st[l] |= SINGULAR_BIT
                tsg[l] = @[tl]
                alive = False
            if not alive:
                @@kill_lane
            elif (st[l] & CONTACT_BIT) == 0:
                ts = @[tl]
                @@contact_check
            @@contact_switch
            if iout[l] < nout and @[tl] == t_out[iout[l]]:
                @[lnd] = 1.0
                @[itw] = iout[l]
                nland += 1
                iout[l] += 1
            if iout[l] >= nout or not alive:
                @[dne] = 1.0
                ndone += 1
            else:
                nrun += 1
        # Tracking at each lane's state (one met again is skipped), every lane at once.
        for l in range(nl):  # lanes: independent
            @@track_accepted
        for l in range(nl):
            @@track_fixup
        @@outputs_feed
        if nland > 0 and out_q.shape[1] > 0:  # none without histories (0 times)
            group_outputs_landed_SUFFIX(
                W, nl, QROW, LAMROW, TLROW, out_q, out_v, out_jf, out_cf, out_dtq, out_cerr,
                out_en@CT
            )
        if ndone > 0:
            # Finished or dead: its queued dense output points written (every lane's); the
            # rest of a dead lane's history is NaN; the lane takes the next sample, if any.
            group_dense_SUFFIX(
                W, nl, t_out, iout, dense, A, cc, balpha2, bbeta2, tau, run, nev, True,
                out_q, out_v, out_jf, out_cf, out_dtq, out_cerr, out_en@CT
            )
            for l in range(nl):
                if @[dne] == 0.0:
                    continue
                sl = int(@[smp])
                nan_history(sl, iout[l], out_q, out_v, out_jf, out_cf, out_dtq, out_cerr, out_en)
                @@contact_dead
                nsteps_out[sl] = nstp[l] - nrej[l]
                nrejected_out[sl] = nrej[l]
                nevals_out[sl] = nev[l]
"""
    + lanes_block(LANE_FINISH, 16)
    + """
                sl = take_next(queue)
                if sl < stop:
                    for r in range(NROW):
                        W[r * LMAXV + l] = 0.0
"""
    + lanes_block(LANE_SETUP, 20)
    + "\n"
    + lanes_block(ADAPTIVE_LANE_START, 20)
    + """
                    nfresh += 1
                    nrun += 1
                else:
                    run[l] = False
                    @[dne] = 0.0
        if nfresh > 0:
            continue  # the fresh lanes' start: its checks and outputs first
        if nrun == 0:
            break
        @@contact_reseat
        # One attempted step on every running lane: stages 1 .. NSTAGE-1.
        for l in range(nl):
            if run[l]:
                @[hs] = min(hl[l], t_out[nout - 1] - @[tl])
            else:
                @[hs] = 0.0
        group_stage_SUFFIX(W, nl, 1, NSTAGE, A, cc, balpha2, bbeta2, tau, run, nev)
        # Error estimate of every lane at once, then acceptance and next step per lane.
        @@error_coefs
        for l in range(nl):  # lanes: schedule
            @@new_state
        for l in range(nl):  # lanes: schedule
            @@error_norm
        for l in range(nl):
            if not run[l]:
                continue
            hh = @[hs]
            en = @[en]
            nstp[l] += 1
            ok = en <= 1.0
            fac = SAFETY * en**expo if en > en_cap else MAX_FACTOR
            fac = min(MAX_FACTOR, max(MIN_FACTOR, fac))
            if not ok:
                fac = min(fac, 1.0)
            @@contact_event
            target = t_out[nout - 1]
            landed = hh == target - @[tl]
            cut = hh < hl[l]
            if ok:
                @@contact_save
                @@contact_accept
                @@accept
                @[acc] = 1.0
                @[ta] = @[tl]
                @[tl] = target if landed else @[tl] + hh
                # A step cut short to land on t_end keeps the controller's step.
                hl[l] = max(hl[l], hh * fac) if cut else hh * fac
            else:
                hl[l] = hh * fac
                nrej[l] += 1
            if (not (hl[l] >= hmin)) or nstp[l] > max_steps:
                @[chk] = np.inf
        # The output times inside the accepted steps (their dense output reads the step's
        # start and stages: before the new state is copied in; λ is copied first).
        for l in range(nl):  # lanes: independent
            @@accept_lam
        ndense = 0
        for l in range(nl):
            ndense += 1 if @[acc] > 0.0 and iout[l] < nout and t_out[iout[l]] < @[tl] else 0
        if ndense > 0:
            group_dense_SUFFIX(
                W, nl, t_out, iout, dense, A, cc, balpha2, bbeta2, tau, run, nev, False,
                out_q, out_v, out_jf, out_cf, out_dtq, out_cerr, out_en@CT
            )
        for l in range(nl):  # lanes: independent
            @@accept_copy"""
)


OUTPUT_LANDED_HELPER = '''
@njit(**JIT)
def group_outputs_landed_SUFFIX(W, nl, qrow, lamrow, trow, out_q, out_v, out_jf, out_cf,
                                out_dtq, out_cerr, out_en@CT):
    """Outputs of the lanes flagged ``lnd`` (1.0), each at its own time (row ``trow``: tl on
    an accepted state, tdn on a dense output) and state (q, v from row ``qrow``: q or ys; λ
    from row ``lamrow``: lam or lamc) into its sample's (row ``smp``) history index (row
    ``itw``): every lane computed at once into rows ``ost`` (a vectorised loop; with the
    stores to the histories in it, a branch on the flag and a scatter, it ran lane by lane:
    reading.md, tenth stop), then the flagged ones stored, lane by lane."""
    for l in range(nl):  # lanes: independent
        t_now = W[(trow + 0) * LMAXV + l]
        @@load_params
        @@load_state_dyn
        @@load_lam_dyn
        @@outputs
        @@stage_outputs
    for l in range(nl):
        if @[lnd] > 0.0:
            sl = int(@[smp])
            it = int(@[itw])
            @@store_staged_outputs
            @@prefetch_outputs
'''

DENSE_HELPER = '''
@njit(**JIT)
def dense_round_SUFFIX(W, nl, A, cc, balpha2, bbeta2, tau, run, nev, out_q, out_v, out_jf,
                       out_cf, out_dtq, out_cerr, out_en@CT):
    """The oldest queued dense output point of every lane that has one, all at once: its
    state into rows ys (its time tdn, its history index itw, its step's contact state in
    the contact rows, theirs held in rows dhd), one evaluation of the stage there (stage
    NSTAGE of group_stage: λ, the contact's rates), its history point (group_outputs_landed
    at rows ys, lamc, tdn), the contact rows back."""
    for l in range(nl):
        @[lnd] = 0.0
        if @[dqc] == 0.0:
            continue
        slot = DQROW + int(@[dqh]) * DQWIDTH
        @@dense_pop
        @[lnd] = 1.0
        @[dqh] = 0.0 if @[dqh] + 1.0 == DQSLOTS else @[dqh] + 1.0
        @[dqc] = @[dqc] - 1.0
    group_stage_SUFFIX(W, nl, NSTAGE, NSTAGE + 1, A, cc, balpha2, bbeta2, tau, run, nev)
    group_outputs_landed_SUFFIX(
        W, nl, YSROW, LAMCROW, TDNROW, out_q, out_v, out_jf, out_cf, out_dtq, out_cerr,
        out_en@CT
    )
    for l in range(nl):
        if @[lnd] > 0.0:
            @@dense_restore


@njit(**JIT)
def group_dense_SUFFIX(W, nl, t_out, iout, dense, A, cc, balpha2, bbeta2, tau, run, nev,
                       flush, out_q, out_v, out_jf, out_cf, out_dtq, out_cerr, out_en@CT):
    """The output times inside each lane's accepted step (row acc; rows ta .. tl, step hs)
    queued as dense output points (the step's continuous extension, ``dense``:
    Tableau.dense), then rounds of dense_round while every running lane has a point queued
    (the group's evaluation serves as many points as it has lanes), or until no point is
    left with ``flush`` (a lane's sample is to change). A full queue calls a round before
    it takes another point. Without histories the output times are passed."""
    nout = t_out.shape[0]
    if out_q.shape[1] == 0:
        for l in range(nl):
            while @[acc] > 0.0 and iout[l] < nout and t_out[iout[l]] < @[tl]:
                iout[l] += 1
        return
    for l in range(nl):
        while @[acc] > 0.0 and iout[l] < nout and t_out[iout[l]] < @[tl]:
            if @[dqc] == DQSLOTS:
                dense_round_SUFFIX(
                    W, nl, A, cc, balpha2, bbeta2, tau, run, nev, out_q, out_v, out_jf,
                    out_cf, out_dtq, out_cerr, out_en@CT
                )
            tail = int(@[dqh] + @[dqc])
            slot = DQROW + (tail - DQSLOTS if tail >= DQSLOTS else tail) * DQWIDTH
            tk = t_out[iout[l]]
            it = float(iout[l])
            hh = @[hs]
            th = (tk - @[ta]) / hh
            @@dense_push
            @[dqc] = @[dqc] + 1.0
            iout[l] += 1
    while True:
        nq = 0
        nr = 0
        for l in range(nl):
            nq += 1 if @[dqc] > 0.0 else 0
            nr += 1 if run[l] else 0
        if nq == 0 or (nq < nr and not flush):
            return
        dense_round_SUFFIX(
            W, nl, A, cc, balpha2, bbeta2, tau, run, nev, out_q, out_v, out_jf, out_cf,
            out_dtq, out_cerr, out_en@CT
        )
'''

STAGE_HELPER = '''
@njit(**JIT)
def group_stage_SUFFIX(W, nl, s_first, s_stop, A, cc, balpha2, bbeta2, tau, run, nev):
    """Stages ``s_first`` … ``s_stop`` − 1 (nodes ``cc``) of every lane at its own time and
    step (rows ``tl``, ``hs``), each from its state (rows ys, summed first: ``stage_state``):
    its k into its rows kq_s, kv_s (stage 0's into kqc, kvc), the current stage's lamc, chkc,
    sgc (with contact joints pdc, prc, wjc, wcc); after each stage s > 0 the step's rank-loss
    count (sga), contact stiffness (wca) and the running lanes' evaluations (``nev``). The
    step's stages in one call: the constants the stage's loop holds in registers or on the
    stack are set up once a step, not once a stage (a lane group is a few registers of
    lanes: a stage's loop runs a few times a call). One copy of the stage for the adaptive
    loop and the first stage: numba's compile time grows faster than the length of a
    function."""
    for s in range(s_first, s_stop):
        dense = s == NSTAGE  # the dense output's evaluation (group_dense), at its own time
        cs = 1.0 if dense else cc[s]
        @@stage_state
        for l in range(nl):  # lanes: schedule
            hh = @[hs]
            ts = @[tdn] if dense else @[tl] + cs * hh
            @@load_params
            @@load_stage
            @@accel_stage
            @@store_stage
        if 0 < s < NSTAGE:  # the step's stages (not a dense output's evaluation)
            keep = 0.0 if s == 1 else 1.0
            for l in range(nl):
                @[sga] = @[sga] * keep + @[sgc]
                @@contact_stage_max
                nev[l] += 1 if run[l] else 0
'''

FIRST_STAGE_HELPER = '''
@njit(**JIT)
def group_first_stage_SUFFIX(W, nl, A, balpha2, bbeta2, tau):
    """Stage 0 at the state of the lanes flagged ``fsm`` (later steps reuse their last
    stage): a fresh sample's start, or a just re-seated state. The other lanes' step and
    current-stage rows, which it also writes, are written again before they are read."""
    for l in range(nl):
        @[hs] = 0.0
    # stage 0 alone, at node 0: no step's counts
    nodes = np.zeros(1)
    idle = np.zeros(LMAXV, np.bool_)
    counts = np.zeros(LMAXV, np.int64)
    group_stage_SUFFIX(W, nl, 0, 1, A, nodes, balpha2, bbeta2, tau, idle, counts)
    for l in range(nl):
        if @[fsm] == 0.0:
            continue
        @@accept_zero
        @@contact_stage_max
'''
