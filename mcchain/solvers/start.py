"""The start state of a time history (item 3 of the contract of
:func:`mcchain.solvers.simulate.simulate`): the model's assembled state or the one passed,
each contact-law journal the scene does not write placed where its ``[joint.contact] start``
says (:func:`contact_start`), ``[simulate] perturb`` added to named coordinates and the
others projected back onto the constraints; and the mode each contact-law joint starts in,
the same for every method.
"""

from __future__ import annotations

import re

import numpy as np

from mcchain.errors import SceneError
from mcchain.model import Model
from mcchain.scene.models import Simulate
from mcchain.solvers.threads import over_samples
from mcchain.status import ASSEMBLY_FAILED, FAILURE_BITS

_PERTURB = re.compile(
    r"^body\.(?P<name>[^.\[\]]+)\."
    r"(?P<key>position\[[01]\]|angle|velocity\[[01]\]|angular_velocity)$"
)


def perturbation_index(model: Model, path: str) -> tuple[str, int]:
    """``("q" | "v", coordinate index)`` of a ``perturb`` path."""
    m = _PERTURB.match(path)
    if not m:
        raise SceneError(
            f"simulate.perturb.{path}: not a coordinate; use body.<name>.position[0|1], "
            "body.<name>.angle, body.<name>.velocity[0|1] or body.<name>.angular_velocity"
        )
    name, key = m.group("name"), m.group("key")
    if name not in model.body_names:
        raise SceneError(f"simulate.perturb.{path}: no body named {name!r}")
    b = model.body_names.index(name)
    table = {
        "position[0]": ("q", 0),
        "position[1]": ("q", 1),
        "angle": ("q", 2),
        "velocity[0]": ("v", 0),
        "velocity[1]": ("v", 1),
        "angular_velocity": ("v", 2),
    }
    which, k = table[key]
    return which, 3 * b + k


def start_state(
    model: Model,
    settings: Simulate,
    q_start: np.ndarray | None = None,
    v_start: np.ndarray | None = None,
    status: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Start positions and velocities (nsample, ndof) and the status, after the contact start
    (:func:`contact_start`) and the perturbation."""
    n, ndof = model.nsample, model.ndof
    q = np.array(np.broadcast_to(model.q0 if q_start is None else q_start, (n, ndof)), float)
    v = np.array(np.broadcast_to(model.v0 if v_start is None else v_start, (n, ndof)), float)
    status = np.zeros(n, np.uint32) if status is None else status.astype(np.uint32).copy()
    q, v, status = contact_start(model, q, v, status)
    if not settings.perturb:
        return q, v, status
    modes = start_modes(model, q)  # of the state before the perturbation
    fixed_q: list[int] = []
    fixed_v: list[int] = []
    for path, value in settings.perturb.items():
        which, i = perturbation_index(model, path)
        (q if which == "q" else v)[:, i] += value
        (fixed_q if which == "q" else fixed_v).append(i)
    return (*_project_start(model, q, v, fixed_q, fixed_v, status, modes),)


def contact_start(
    model: Model, q: np.ndarray, v: np.ndarray, status: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The state (q, v: (nsample, 3 nbody), status (nsample,) uint32) with each contact-law
    journal that the scene does not write (``Model.joint_written`` 0) placed where its
    ``[joint.contact] start`` (``Model.joint_contact_start``) says: pressed along the ideal
    mechanism's joint force at t = 0 by the δ₀ whose force K δ₀^m balances it, centred
    (d = 0), or seated (as assembled); the rest of the mechanism closed again around it,
    every held journal at rest in its bearing (:mod:`mcchain.kernels.start`). Unchanged,
    without calling a kernel, where every such journal starts seated (model auto by default,
    and every scene without a law).
    """
    from mcchain.contact import LINK, PLACE_CODES, PLACE_SEATED

    place = np.array(
        [
            PLACE_CODES[name] if model.joint_model[k] != LINK and model.joint_written[k] == 0
            else PLACE_SEATED
            for k, name in enumerate(model.joint_contact_start)
        ],
        dtype=np.int64,
    )  # fmt: skip
    if not np.any(place != PLACE_SEATED) or not model.nsample:
        return q, v, status
    from mcchain.kernels.start import place_journals_batch

    # C order: numba compiles per layout, and a copy of a broadcast start is F-ordered
    q, v = np.ascontiguousarray(q), np.ascontiguousarray(v)
    status = np.ascontiguousarray(status, dtype=np.uint32)
    over_samples(place_journals_batch, model.nsample, model.kernel_model(), place, q, v, status)
    return q, v, status


def start_modes(model: Model, q: np.ndarray) -> np.ndarray:
    """The mode each contact-law joint starts in, (nsample, njoint) float64
    (``Model.joint_start``), from the start positions q (nsample, 3 nbody).

    A journal with |δ| ≤ :func:`mcchain.contact.seat_tolerance` is on the wall: model
    contact starts seated under the law (``START_SEATED``), model auto on the link
    (``START_LINK``; its kernels switch to the law at once where the link's λ ≤ 0). A journal
    off the wall (free or pressed) starts under the law (``START_LAW``), whatever the
    model. Other joints: ``START_LINK``.
    """
    from mcchain.contact import CONTACT as MODEL_CONTACT
    from mcchain.contact import SEAT_TOLERANCE, START_LAW, START_LINK, START_SEATED

    n = q.shape[0]
    modes = np.full((n, model.njoint), float(START_LINK))
    for k in np.flatnonzero(model.joint_model):
        delta = _penetration(model, q, int(k))
        clearance = np.broadcast_to(model.joint_clearance[:, k], (n,))
        seated = np.abs(delta) <= SEAT_TOLERANCE * clearance
        on_wall = START_SEATED if model.joint_model[k] == MODEL_CONTACT else START_LINK
        modes[:, k] = np.where(seated, float(on_wall), float(START_LAW))
    return modes


def _penetration(model: Model, q: np.ndarray, k: int) -> np.ndarray:
    """δ = |d| − c of joint ``k`` at the positions q (nsample, 3 nbody), (nsample,) m."""
    from mcchain.scene.compile import world_point

    n = q.shape[0]
    ends = [
        np.broadcast_to(world_point(q, int(body), np.broadcast_to(points[:, k], (n, 2))), (n, 2))
        for body, points in ((model.joint_body_b[k], model.joint_point_b),
                             (model.joint_body_a[k], model.joint_point_a))
    ]  # fmt: skip
    d = ends[0] - ends[1]
    return np.hypot(d[:, 0], d[:, 1]) - np.broadcast_to(model.joint_clearance[:, k], (n,))


def _project_start(
    model: Model,
    q: np.ndarray,
    v: np.ndarray,
    fixed_q: list[int],
    fixed_v: list[int],
    status: np.ndarray,
    modes: np.ndarray | None = None,
    tol: float = 1e-13,
    iterations: int = 30,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Project q then v onto Φ = 0, B v = ν at t = 0 holding the given coordinates fixed.

    Gauss–Newton with minimum-norm (M-weighted) corrections of the free coordinates; a
    sample that does not converge gets ASSEMBLY_FAILED and NaN. ``modes`` (nsample, njoint),
    :func:`start_modes` before the perturbation: a joint starting under the law has no
    velocity row, and one off its wall (``START_LAW``) no position row either (its journal
    stays free or pressed as it was).
    """
    from mcchain.contact import START_LAW, START_LINK
    from mcchain.kernels.forces import mass_diagonal
    from mcchain.kernels.joints import (
        constraint_jacobian,
        constraint_residual,
        constraint_velocity_rhs,
    )

    km = model.kernel_model()
    # rows of C-ordered arrays: the kernels below are compiled for those (contact_start may
    # hand over other strides, which would compile each of them once more)
    q = np.ascontiguousarray(q)
    v = np.ascontiguousarray(v)
    ncon, ndof = model.ncon, model.ndof
    phi = np.zeros(ncon)
    B = np.zeros((ncon, ndof))
    nu = np.zeros(ncon)
    m = np.zeros(ndof)
    free_q = np.ones(ndof, bool)
    free_q[fixed_q] = False
    free_v = np.ones(ndof, bool)
    free_v[fixed_v] = False
    modes = np.zeros((model.nsample, model.njoint)) if modes is None else modes
    for s in range(model.nsample):
        if status[s] & FAILURE_BITS:
            continue
        rows_q = np.ones(ncon, bool)  # the rows that constrain this sample's start
        rows_v = np.ones(ncon, bool)
        rows_q[model.joint_row[modes[s] == START_LAW]] = False
        rows_v[model.joint_row[modes[s] != START_LINK]] = False
        mass_diagonal(km, s, m)
        ok = False
        for _ in range(iterations):
            constraint_residual(km, s, q[s], 0.0, phi)
            if np.max(np.abs(phi[rows_q]), initial=0.0) <= tol:
                ok = True
                break
            constraint_jacobian(km, s, q[s], B)
            W = B[np.ix_(rows_q, free_q)] / m[free_q]
            step = np.linalg.lstsq(W * m[free_q] @ W.T, phi[rows_q], rcond=1e-12)[0]
            q[s, free_q] -= W.T @ step
        if not ok or not np.all(np.isfinite(q[s])):
            status[s] |= ASSEMBLY_FAILED
            q[s] = np.nan
            v[s] = np.nan
            continue
        constraint_jacobian(km, s, q[s], B)
        constraint_velocity_rhs(km, s, 0.0, nu)
        W = B[np.ix_(rows_v, free_v)] / m[free_v]
        res = (B @ v[s] - nu)[rows_v]
        v[s, free_v] -= W.T @ np.linalg.lstsq(W * m[free_v] @ W.T, res, rcond=1e-12)[0]
    return q, v, status
