"""Drawable geometry of a :class:`~mcchain.model.Model`: body outlines and world points.

A model knows no shapes, only points: the joint, spring and force attachment points of each
body (local coordinates) and its centre of mass (local origin). A body is drawn as line strips
through those points:

* points on one line (a bar, a crank): one open strip, sorted along the line;
* otherwise (a plate with three joints): the closed loop of the convex hull, plus a spoke from
  every point inside the hull (the centre of mass, usually) to its nearest hull vertex.

Sampled geometry (``joint.B.points[1][0]`` varied) is honoured: every function takes the
model *row* of the sample, read with the broadcast index ``row % a.shape[0]``.

World positions: a local point ``s`` on body ``i`` is at
``r_i + A(θ_i) s``; the ground (index ``GROUND``) is fixed, ``r = 0``, ``θ = 0``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mcchain.model import GROUND, JOINT_CLEARANCE, Model

COLLINEAR_RTOL = 1e-9
"""Second singular value below this fraction of the first: the points are on one line."""


@dataclass(frozen=True)
class BodyOutline:
    """The line strips that draw one body, in its local frame (m).

    Attributes:
        body: body index in the model.
        name: body name.
        strips: each an array (k, 2) of local points, k >= 2 (a lone centre of mass is drawn
            as a degenerate strip of two equal points).
    """

    body: int
    name: str
    strips: tuple[np.ndarray, ...]


def _at(arr: np.ndarray, row: int) -> np.ndarray:
    """Sample ``row`` of a parameter array with a leading sample axis of size 1 or nsample."""
    return np.asarray(arr[row % arr.shape[0]], dtype=np.float64)


def body_local_points(model: Model, body: int, row: int = 0) -> np.ndarray:
    """Local points (k, 2) of ``body``: its centre of mass first, then every attachment.

    Attachments are the joint points (as bearing or journal), spring ends and force points
    that the model puts on this body; duplicates are removed (keeping the first).
    """
    pts: list[np.ndarray] = [np.zeros(2)]
    jpa, jpb = _at(model.joint_point_a, row), _at(model.joint_point_b, row)
    for k in range(model.njoint):
        if model.joint_body_a[k] == body:
            pts.append(jpa[k])
        if model.joint_body_b[k] == body:
            pts.append(jpb[k])
    spa, spb = _at(model.spring_point_a, row), _at(model.spring_point_b, row)
    for k in range(model.nspring):
        if model.spring_body_a[k] == body:
            pts.append(spa[k])
        if model.spring_body_b[k] == body:
            pts.append(spb[k])
    fp = _at(model.force_point, row)
    for k in range(model.nforce):
        if model.force_body[k] == body:
            pts.append(fp[k])
    out = np.array(pts, dtype=np.float64).reshape(-1, 2)
    _, first = np.unique(np.round(out, 12), axis=0, return_index=True)
    return out[np.sort(first)]


def _hull_order(points: np.ndarray) -> np.ndarray:
    """Indices of the convex hull of ``points`` (n, 2), counter-clockwise (monotone chain)."""
    order = np.lexsort((points[:, 1], points[:, 0]))

    def cross(o: int, a: int, b: int) -> float:
        oa = points[a] - points[o]
        ob = points[b] - points[o]
        return float(oa[0] * ob[1] - oa[1] * ob[0])

    lower: list[int] = []
    for i in order:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], int(i)) <= 0:
            lower.pop()
        lower.append(int(i))
    upper: list[int] = []
    for i in order[::-1]:
        while len(upper) >= 2 and cross(upper[-2], upper[-1], int(i)) <= 0:
            upper.pop()
        upper.append(int(i))
    return np.array(lower[:-1] + upper[:-1], dtype=np.int64)


def outline_strips(points: np.ndarray) -> tuple[np.ndarray, ...]:
    """Line strips through the local points (k, 2) of one body (see the module docstring)."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if len(points) == 1:
        return (np.repeat(points, 2, axis=0),)
    centred = points - points.mean(axis=0)
    _, sv, vt = np.linalg.svd(centred, full_matrices=False)
    if len(sv) < 2 or sv[1] <= COLLINEAR_RTOL * max(sv[0], np.finfo(float).tiny):
        along = centred @ vt[0]
        return (points[np.argsort(along, kind="stable")],)
    hull = _hull_order(points)
    strips = [points[np.append(hull, hull[0])]]
    for i in range(len(points)):
        if i not in hull:
            nearest = hull[np.argmin(np.linalg.norm(points[hull] - points[i], axis=1))]
            strips.append(points[[i, nearest]])
    return tuple(strips)


def body_outlines(model: Model, row: int = 0) -> list[BodyOutline]:
    """The outline of every body of the model for the sample at model row ``row``."""
    return [
        BodyOutline(b, model.body_names[b], outline_strips(body_local_points(model, b, row)))
        for b in range(model.nbody)
    ]


def to_world(local: np.ndarray, pose: np.ndarray | None) -> np.ndarray:
    """World positions of local points on a moving body.

    Args:
        local: (k, 2) local points, m.
        pose: (T, 3) the body's [X, Y, θ] at T instants; ``None`` for the ground.

    Returns:
        (T, k, 2) world positions (for the ground: (1, k, 2), the points themselves).
    """
    local = np.asarray(local, dtype=np.float64).reshape(-1, 2)
    if pose is None:
        return local[None].copy()
    pose = np.asarray(pose, dtype=np.float64).reshape(-1, 3)
    c, s = np.cos(pose[:, 2])[:, None], np.sin(pose[:, 2])[:, None]
    x = pose[:, 0, None] + c * local[None, :, 0] - s * local[None, :, 1]
    y = pose[:, 1, None] + s * local[None, :, 0] + c * local[None, :, 1]
    return np.stack([x, y], axis=-1)


def point_world(body: int, local: np.ndarray, q: np.ndarray) -> np.ndarray:
    """World positions (T, 2) of one local point on ``body`` over the poses ``q`` (T, nbody, 3)."""
    if body == GROUND:
        return np.broadcast_to(np.asarray(local, dtype=np.float64), (q.shape[0], 2)).copy()
    return to_world(np.asarray(local).reshape(1, 2), q[:, body])[:, 0]


@dataclass(frozen=True)
class JointTrack:
    """Where the joints are over time (world frame, m).

    Attributes:
        bearing: (T, njoint, 2) bearing centres, on body a.
        journal: (T, njoint, 2) journal centres, on body b.
        drawn: (T, njoint, 2) the journal as drawn: bearing + ``magnify`` · d for clearance
            joints, the journal itself for ideal ones.
        circle_radius: (njoint,) drawn radius of the bearing circle, ``magnify`` · c for
            clearance joints, 0 for ideal ones.
    """

    bearing: np.ndarray
    journal: np.ndarray
    drawn: np.ndarray
    circle_radius: np.ndarray


def joint_track(model: Model, row: int, q: np.ndarray, magnify: float) -> JointTrack:
    """Bearing and journal centres of every joint over the poses ``q`` (T, nbody, 3).

    The journal offset ``d = journal − bearing`` of a clearance joint has the size of the
    clearance (0.1 mm); it is drawn ``magnify`` times longer so that it can be seen.
    """
    nt = q.shape[0]
    jpa, jpb = _at(model.joint_point_a, row), _at(model.joint_point_b, row)
    clearance = _at(model.joint_clearance, row)
    bearing = np.empty((nt, model.njoint, 2))
    journal = np.empty((nt, model.njoint, 2))
    for k in range(model.njoint):
        bearing[:, k] = point_world(int(model.joint_body_a[k]), jpa[k], q)
        journal[:, k] = point_world(int(model.joint_body_b[k]), jpb[k], q)
    is_clear = np.asarray(model.joint_kind) == JOINT_CLEARANCE
    drawn = np.where(is_clear[None, :, None], bearing + magnify * (journal - bearing), journal)
    radius = np.where(is_clear, magnify * clearance.reshape(-1)[: model.njoint], 0.0)
    return JointTrack(bearing, journal, drawn, radius)


def circles(centres: np.ndarray, radius: float, npoint: int = 33) -> np.ndarray:
    """Closed circles (T, npoint, 2) of ``radius`` around each of the centres (T, 2)."""
    phi = np.linspace(0.0, 2.0 * np.pi, npoint)
    ring = radius * np.stack([np.cos(phi), np.sin(phi)], axis=-1)
    return np.asarray(centres)[:, None, :] + ring[None]


def characteristic_length(model: Model, row: int = 0) -> float:
    """A length scale of the mechanism (m): the largest extent of any body's points, at least
    the distance of any ground anchor from the origin; 1 if the model has no extent at all."""
    extent = 0.0
    for b in range(model.nbody):
        pts = body_local_points(model, b, row)
        extent = max(extent, float(np.ptp(pts, axis=0).max()) if len(pts) > 1 else 0.0)
    jpa = _at(model.joint_point_a, row)
    for k in range(model.njoint):
        if model.joint_body_a[k] == GROUND:
            extent = max(extent, float(np.linalg.norm(jpa[k])))
    return extent if extent > 0.0 else 1.0


def normalised_offsets(model: Model, row: int, q: np.ndarray) -> np.ndarray:
    """The journal orbit: ``d / c`` of every joint over the poses ``q`` (T, nbody, 3).

    ``d`` = journal centre − bearing centre (world frame, :func:`joint_track`), ``c`` the
    joint's radial clearance, so the clearance circle is the unit circle (|d|/c > 1 is a
    penetration under a contact law). Returns (T, njoint, 2), dimensionless; NaN for ideal
    joints.
    """
    jt = joint_track(model, row, q, 1.0)
    clearance = _at(model.joint_clearance, row).reshape(-1)[: model.njoint]
    is_clear = (np.asarray(model.joint_kind) == JOINT_CLEARANCE) & (clearance > 0.0)
    scale = np.where(is_clear, clearance, np.nan)
    return (jt.journal - jt.bearing) / scale[None, :, None]
