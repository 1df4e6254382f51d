"""Clearance joints under the contact law in the generic (loop) kernels: per joint, the law's
force at a state, and the bookkeeping of its modes between steps.

The generated lane kernels do the same in straight-line code (``mcchain.codegen``); these
functions follow them step for step, so the loop path and the lanes agree to rounding. A
joint of model contact or auto (``km.joint_model`` ≠ 0) keeps its constraint row; while the
law holds (``FM`` = 1) that row's equation is λ_r = F_n (:func:`law_rows`), so −F_n n acts on
the journal (body b) and +F_n n on the bearing (body a), and the row imposes nothing.

State of one sample: ``cst`` (ncj, NCST) float, one row per contact-law joint (in joint
order), columns named below. Rules every kernel keeps: no allocation, never raise.
"""

from __future__ import annotations

import math

from mcchain.contact import (
    AUTO,
    RESEAT_PERIODS,
    SEAT_TOLERANCE,
    SEATED,
    SEATED_AT_SWITCH,
    START_LINK,
    START_SEATED,
)
from mcchain.kernels.config import INLINE, JIT, hypot, njit
from mcchain.kernels.contact import (
    contact_bookkeeping,
    contact_law,
    contact_slip,
    friction_force,
    reseat_slack,
)
from mcchain.kernels.joints import joint_separation_rate, joint_vectors

# Columns of ``cst``: the mode and the contact in progress ...
FM = 0  # 1.0 while the law replaces the link (model contact, or auto after its switch)
INS = 1  # 1.0 if the journal was in contact (δ > 0) at the last step's start
VI = 2  # approach speed δ̇⁻ of the contact in progress (m/s), located at its onset; < 0:
# seated (a contact from a start on the wall or from the link: undamped, no onset, until the
# journal is off the wall by more than mcchain.contact.seat_tolerance; SEATED_AT_SWITCH: from
# the link, free flight from the switch while within the tolerance)
PD = 3  # δ (m) and δ̇ (m/s) at the last bookkeeping (the previous step's start)
PR = 4
PDC = 5  # δ, δ̇ and ω_c² (1/s²) at the current step's start (its first stage)
PRC = 6
WJC = 7
DWL = 8  # time pressed quasi-statically so far (s); −1: marked for re-seating
# ... the values of the last stage evaluated ...
PEN = 9  # δ, m
PDOT = 10  # δ̇, m/s
FN = 11  # F_n, N
KC = 12  # FM · ∂F_n/∂δ, N/m (the step-size check)
# ... and the summaries (mcchain.contact.CONTACT_SUMMARY, in that order).
DFR = 13  # FM · ∂F_n/∂δ̇, N s/m (Newton iterations of implicit steps)
NIM = 14  # impacts
PKF = 15  # peak contact force, N (the continuous one, mcchain.kernels.peaks, at the end)
PKD = 16  # peak penetration, m (continuous: on each step's Hermite interpolant)
TFF = 17  # free-flight time, s
TSE = 18  # first separation time, s
NCST = 19
SUMMARY_COLUMNS = (NIM, PKF, PKD, TFF, TSE)


@njit(**JIT)
def contact_joints(km):
    """Number of contact-law joints (``km.joint_model`` ≠ 0); they are the first that many
    entries of :func:`contact_joint_index`'s answer."""
    count = 0
    for k in range(km.joint_model.shape[0]):
        if km.joint_model[k] != 0:
            count += 1
    return count


@njit(**JIT)
def contact_joint_index(km, j):
    """Joint index of the ``j``-th contact-law joint."""
    count = 0
    for k in range(km.joint_model.shape[0]):
        if km.joint_model[k] != 0:
            if count == j:
                return k
            count += 1
    return -1


@njit(**JIT)
def contact_start(km, s, cst):
    """The state at t0 of sample ``s``: each joint in the mode it starts in
    (``km.joint_start``: the link, the law, or the law seated on the wall; a contact present
    at t0 has no onset: INS 1, undamped), no step behind (δ, δ̇, first separation: NaN),
    summaries 0."""
    for j in range(cst.shape[0]):
        k = contact_joint_index(km, j)
        for c in range(NCST):
            cst[j, c] = 0.0
        start = km.joint_start[s % km.joint_start.shape[0], k]
        cst[j, FM] = 1.0 if start != START_LINK else 0.0
        cst[j, INS] = cst[j, FM]
        cst[j, VI] = SEATED if start == START_SEATED else 0.0
        cst[j, PD] = math.nan
        cst[j, PR] = math.nan
        cst[j, TSE] = math.nan


@njit(**JIT)
def contact_forces(km, s, q, v, cst, F_out):
    """δ, δ̇, F_n and its partial derivatives of every contact-law joint at (q, v) into ``cst``
    (PEN, PDOT, FN, KC, DFR; the derivatives 0 where the force is, or off the law), and the
    regularised Coulomb friction of the joints under the law added to the generalised forces
    ``F_out`` (3 nbody,).

    D comes from the approach speed of the contact in progress (VI, located when it began)
    or, in a step that started in free flight (INS = 0), from the current δ̇: the contact's
    first instants, where the onset is located only at the step's end. Friction: slip of the
    journal's surface point on the bearing's along t = (−n_y, n_x),
    v_t = t·ḋ + R ω_b − (R + c) ω_a; the journal receives F_t t at its contact point, the
    bearing −F_t t at its own (mcchain.kernels.contact.friction_force).
    """
    for j in range(cst.shape[0]):
        k = contact_joint_index(km, j)
        i = s % km.joint_clearance.shape[0]
        c = km.joint_clearance[i, k]
        stiffness = km.joint_contact_stiffness[s % km.joint_contact_stiffness.shape[0], k]
        expo = km.joint_contact_exponent[s % km.joint_contact_exponent.shape[0], k]
        e = km.joint_contact_restitution[s % km.joint_contact_restitution.shape[0], k]
        law = km.joint_contact_law[k]
        a = km.joint_body_a[k]
        b = km.joint_body_b[k]
        pax, pay, pbx, pby, dx, dy = joint_vectors(km, s, q, k)
        ddx, ddy = joint_separation_rate(v, a, b, pax, pay, pbx, pby)
        rho = hypot(dx, dy)
        # at the bearing centre (written there) no normal, and none needed: F_n = 0
        ex = dx / rho if rho > 0.0 else 0.0
        ey = dy / rho if rho > 0.0 else 0.0
        pen = rho - c
        pdot = ex * ddx + ey * ddy
        fn, delta_slope, rate_slope = contact_law(
            pen, pdot, cst[j, INS], cst[j, VI], stiffness, expo, law, e
        )
        cst[j, PEN] = pen
        cst[j, PDOT] = pdot
        cst[j, FN] = fn
        cst[j, KC] = cst[j, FM] * delta_slope
        cst[j, DFR] = cst[j, FM] * rate_slope
        mu = km.joint_contact_friction[s % km.joint_contact_friction.shape[0], k]
        if cst[j, FM] != 1.0 or mu == 0.0:
            continue
        radius = km.joint_contact_radius[s % km.joint_contact_radius.shape[0], k]
        tx = -ey
        ty = ex
        wa = v[3 * a + 2] if a >= 0 else 0.0
        wb = v[3 * b + 2] if b >= 0 else 0.0
        slip = contact_slip(ex, ey, ddx, ddy, radius, c, wa, wb)
        ft = friction_force(fn, slip, mu)
        ftx = ft * tx
        fty = ft * ty
        if b >= 0:
            F_out[3 * b] += ftx
            F_out[3 * b + 1] += fty
            F_out[3 * b + 2] += pbx * fty - pby * ftx + radius * ft
        if a >= 0:
            F_out[3 * a] -= ftx
            F_out[3 * a + 1] -= fty
            F_out[3 * a + 2] -= pax * fty - pay * ftx + (radius + c) * ft


@njit(**JIT)
def law_rows(km, cst, row_law):
    """``row_law`` (ncon, 3): column 0 = 1.0 on the row of a joint under the law (its
    equation λ_r = F_n), column 1 = its F_n; other rows 0 (column 2 is written by the
    Schur solve: S_rr before the replacement)."""
    for r in range(row_law.shape[0]):
        row_law[r, 0] = 0.0
        row_law[r, 1] = 0.0
    for j in range(cst.shape[0]):
        r = km.joint_row[contact_joint_index(km, j)]
        row_law[r, 0] = cst[j, FM]
        row_law[r, 1] = cst[j, FN] * cst[j, FM]


@njit(**INLINE)
def contact_pulsation(km, cst, row_law):
    """max over the joints under the law of ω_c² = ∂F_n/∂δ · S_rr (1/s²; S_rr = 1/m*, the
    inverse effective mass along n), after the Schur solve filled ``row_law[:, 2]``."""
    largest = 0.0
    for j in range(cst.shape[0]):
        r = km.joint_row[contact_joint_index(km, j)]
        largest = max(largest, cst[j, KC] * row_law[r, 2])
    return largest


@njit(**JIT)
def record_stage0(km, cst, row_law):
    """δ, δ̇ and ω_c² of the first stage of a step (its start) into PDC, PRC, WJC."""
    for j in range(cst.shape[0]):
        r = km.joint_row[contact_joint_index(km, j)]
        cst[j, PDC] = cst[j, PEN]
        cst[j, PRC] = cst[j, PDOT]
        cst[j, WJC] = cst[j, KC] * row_law[r, 2]


@njit(**JIT)
def contact_switch(km, cst, j, lam_r, t, d1):
    """Model auto: the law from the first λ ≤ 0 on, starting from the link's state, seated
    (VI < 0: the link's δ is 0 up to rounding; undamped, no onset, until the journal is off
    the wall by more than the seat tolerance)."""
    k = contact_joint_index(km, j)
    if cst[j, FM] == 0.0 and lam_r <= 0.0 and km.joint_model[k] == AUTO:
        cst[j, FM] = 1.0
        cst[j, VI] = SEATED_AT_SWITCH
        cst[j, INS] = 1.0
        if cst[j, TSE] != cst[j, TSE]:
            cst[j, TSE] = t


@njit(**INLINE)
def reseat_margin(km, s, k, lam_r, d1, r1, wn, kinetic):
    """:func:`mcchain.kernels.contact.reseat_slack` of joint ``k`` (under the law) with δ1,
    δ̇1, F_n = ``lam_r``, ω_c = ``wn`` and the kinetic energy ``kinetic``: > 0 exactly where
    it may count this instant towards its re-seat dwell."""
    expo = km.joint_contact_exponent[s % km.joint_contact_exponent.shape[0], k]
    paid = 1.0 if km.driver_row.shape[0] == 0 else 0.0
    return reseat_slack(km.joint_model[k], d1, r1, lam_r, wn, kinetic, expo, paid)


@njit(**INLINE)
def reseat_ready(km, s, k, lam_r, d1, r1, wn, kinetic):
    """Whether joint ``k`` (under the law) may count this instant towards its re-seat dwell
    (:func:`reseat_margin` > 0)."""
    return reseat_margin(km, s, k, lam_r, d1, r1, wn, kinetic) > 0.0


@njit(**JIT)
def contact_step(km, s, cst, j, lam_r, t, h, d1, r1, kinetic):
    """Bookkeeping of the step of length ``h`` that ended at time ``t`` with δ1, δ̇1 and
    the kinetic energy ``kinetic`` (J): onset (δ crosses 0 upwards: located on the cubic
    Hermite interpolant, its rate is δ̇⁻), separation, free flight, peak penetration (the
    interpolant's maximum: :func:`mcchain.kernels.contact.contact_bookkeeping`), and the
    re-seat criterion of model auto (:func:`reseat_ready`). Returns True when the joint is
    marked for re-seating."""
    k = contact_joint_index(km, j)
    marked = False
    if cst[j, FM] == 1.0:
        seat = SEAT_TOLERANCE * km.joint_clearance[s % km.joint_clearance.shape[0], k]
        books = contact_bookkeeping(cst[j, VI], cst[j, INS], cst[j, NIM], cst[j, TFF],
                                    cst[j, TSE], cst[j, PKD], cst[j, PD], cst[j, PR], d1, r1,
                                    h, t, seat)  # fmt: skip
        cst[j, VI], cst[j, INS], cst[j, NIM], cst[j, TFF], cst[j, TSE], cst[j, PKD] = books
        wj = cst[j, WJC]
        wn = math.sqrt(wj) if wj > 0.0 else 0.0
        if reseat_ready(km, s, k, lam_r, d1, r1, wn, kinetic):
            cst[j, DWL] += h
            if cst[j, DWL] * wn >= 2.0 * math.pi * RESEAT_PERIODS:
                cst[j, DWL] = -1.0
                marked = True
        else:
            cst[j, DWL] = 0.0
    cst[j, PD] = d1
    cst[j, PR] = r1
    return marked
