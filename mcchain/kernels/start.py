"""Where a contact-law journal the scene does not write starts (``[joint.contact] start``).

Assembly (:mod:`mcchain.kernels.assembly`) leaves such a journal seated on its wall, in the
direction that presses it (``eccentricity``, else the ideal mechanism's joint force at t = 0),
with no force under the law. :func:`place_journals` then moves it, per joint, to the place its
code (:data:`mcchain.contact.PLACE_CODES`) names:

* pressed: d = (c + δ₀) u, u the assembled d's direction, δ₀ = (f/K)^(1/m) with f = λ·u the
  ideal mechanism's joint force at t = 0 (:func:`~mcchain.kernels.assembly.ideal_joint_multipliers`:
  its KKT solve at the start state, inertia included) along u, so that the law's force at
  t = 0, K δ₀^m (δ̇ = 0: its damping term is 0), balances it; δ₀ = 0 (stays seated) where
  f ≤ 0 or the ideal mechanism cannot be solved. Friction is not part of the balance: where
  the surfaces slip at t = 0 (the bodies turn) it acts from the start;
* centred: d = 0, the journal in the middle of its bearing;
* seated: where assembly put it.

The other joints, prismatic joints and drivers are then closed again around those offsets
(Gauss–Newton, M-smallest corrections, every other clearance journal held where it is) and
the velocities analysed with every held journal at rest in its bearing (ḋ = 0) and the
drivers at their speeds. A journal the scene writes (``km.joint_written``) is not moved, nor
is a sample with nothing to move. Nothing here raises; a sample whose offsets cannot be
closed gets ASSEMBLY_FAILED (and SINGULAR where the Jacobian lost rank) and NaN.
"""

from __future__ import annotations

import numpy as np

from mcchain.contact import PLACE_CENTRED, PLACE_PRESSED
from mcchain.kernels.assembly import (
    _assembly_residual,
    _close_joints,
    _velocities_at_rest_in_bearings,
    ideal_joint_multipliers,
    law_start_joints,
    length_scale,
)
from mcchain.kernels.config import JIT, hypot, njit
from mcchain.kernels.forces import mass_diagonal
from mcchain.kernels.joints import JOINT_CLEARANCE, joint_vectors
from mcchain.status import ASSEMBLY_FAILED, FAILURE_BITS, SINGULAR


@njit(**JIT)
def place_journals(km, s, place, q, v):
    """Move the journals of sample ``s`` to the places ``place`` (njoint,) int64 names, in
    place (q, v: (3 nbody,)). Returns status bits (0: done, or nothing to move)."""
    n = q.shape[0]
    nj = km.joint_body_a.shape[0]
    nd = km.driver_body.shape[0]
    free = np.zeros(nj, dtype=np.bool_)
    seated = np.zeros(nj, dtype=np.bool_)
    nfree = law_start_joints(km, s, q, free, seated)
    lscale = length_scale(km, s)
    minv = np.empty(n)
    mass_diagonal(km, s, minv)
    for i in range(n):
        minv[i] = 1.0 / minv[i]
    pressed = False
    for k in range(nj):
        if km.joint_kind[k] == JOINT_CLEARANCE and not free[k] and place[k] == PLACE_PRESSED:
            pressed = True
    lam = np.zeros(2 * nj + nd)
    solved = pressed and ideal_joint_multipliers(km, s, q, v, minv, lscale, lam) >= 0.0
    target = np.zeros((nj, 2))
    moves = False
    for k in range(nj):
        if km.joint_kind[k] != JOINT_CLEARANCE or free[k]:
            continue
        c = km.joint_clearance[s % km.joint_clearance.shape[0], k]
        _, _, _, _, dx, dy = joint_vectors(km, s, q, k)
        dist = hypot(dx, dy)
        target[k, 0] = dx / c  # held where it is: c target = d
        target[k, 1] = dy / c
        if place[k] == PLACE_CENTRED:
            target[k, 0] = 0.0
            target[k, 1] = 0.0
            moves = True
        elif place[k] == PLACE_PRESSED and solved and dist > 0.0:
            ux, uy = dx / dist, dy / dist
            push = lam[2 * k] * ux + lam[2 * k + 1] * uy  # N, the ideal force along u
            if push > 0.0:
                stiffness = km.joint_contact_stiffness[s % km.joint_contact_stiffness.shape[0], k]
                expo = km.joint_contact_exponent[s % km.joint_contact_exponent.shape[0], k]
                delta0 = (push / stiffness) ** (1.0 / expo)
                target[k, 0] = ux * (1.0 + delta0 / c)  # c target = (c + δ₀) u
                target[k, 1] = uy * (1.0 + delta0 / c)
                moves = True
    if not moves:
        return 0
    ma = 2 * (nj - nfree) + nd
    psi = np.empty(ma)
    J = np.empty((ma, n))
    S = np.empty((ma, ma))
    code = _close_joints(km, s, q, target, free, minv, lscale, psi, J, S)
    if code == 2:
        return ASSEMBLY_FAILED | SINGULAR
    if code != 0:
        return ASSEMBLY_FAILED
    _assembly_residual(km, s, q, target, free, psi, J)
    if not _velocities_at_rest_in_bearings(km, s, J, minv, S, v):
        return ASSEMBLY_FAILED | SINGULAR
    return 0


@njit(**JIT)
def place_journals_batch(start, stop, km, place, q_out, v_out, status_out):
    """:func:`place_journals` on samples ``start:stop`` (q_out, v_out: (nsample, 3 nbody),
    status_out: (nsample,) uint32, bits OR-ed in); samples already failed are skipped, a
    sample that fails here is NaN."""
    for s in range(start, stop):
        if status_out[s] & FAILURE_BITS:
            continue
        bits = place_journals(km, s, place, q_out[s], v_out[s])
        if bits != 0:
            status_out[s] |= bits
            q_out[s, :] = np.nan
            v_out[s, :] = np.nan
