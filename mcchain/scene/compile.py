"""Compile a validated :class:`~mcchain.scene.models.Scene` into a :class:`~mcchain.model.Model`.

The model's parameter arrays have a leading sample axis of size 1, except the arrays a
``[sample.vary]`` path lands in, which get ``nsample`` rows (and arrays derived from a varied
value: a driver's default ``angle0`` follows its body's sampled angle, a spring's default
rest length follows sampled positions/points). Where each path lands, and the array each
scene key fills, is its row's Model field in :data:`mcchain.parameters.TABLE`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mcchain.contact import (
    DEFAULT_START,
    LAW_CODES,
    LINK,
    MODEL_CODES,
    internal_cylinder_stiffness,
    seat_tolerance,
)
from mcchain.errors import SceneError
from mcchain.model import DRIVER_LAWS, GROUND, LOAD_LAWS, JointKind, Model, constraint_rows
from mcchain.parameters import PARAMETERS, TABLE
from mcchain.scene.fields import GROUND_NAME
from mcchain.scene.memory import check_memory
from mcchain.scene.models import Scene
from mcchain.scene.outputs import check_output_windows
from mcchain.scene.paths import PARAM_SHAPES, ParamRef, parameter_slot, parse_path, quote_key
from mcchain.scene.sampling import sample_parameters
from mcchain.scene.study import MAX_SEED, saltelli_count_error

Slot = tuple[str, tuple[int, ...]]


def _check_count(name: str, value: int, low: int, high: int | None = None) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer):
        raise SceneError(f"{name}: expected an integer, got {value!r}")
    if value < low or (high is not None and value > high):
        rng = f">= {low}" if high is None else f"in [{low}, {high}]"
        raise SceneError(f"{name}: must be {rng}, got {value}")
    return int(value)


def compile_model(
    scene: Scene,
    nsample: int | None = None,
    seed: int | None = None,
    count_name: str = "nsample",
    parameters: np.ndarray | None = None,
) -> Model:
    """Lay a scene out as a :class:`Model` of ``nsample`` instances.

    Args:
        scene: a validated scene (:func:`mcchain.scene.load_scene`).
        nsample: number of instances; default ``[sample] count``, or 1 without ``[sample]``
            (then every instance is the same and there are no parameters).
        seed: sampling seed; default ``[sample] seed`` (0 without ``[sample]``).
        count_name: how a message names ``nsample`` (``--samples`` from the command line).
        parameters: (nsample, nparam) values of the ``[sample.vary]`` paths to use instead of
            the design's draws (``mcchain rare`` moves its samples itself); default drawn.

    Returns:
        The model; ``parameters`` (nsample, nparam) holds the sampled values in the order of
        ``[sample.vary]`` and ``param_paths`` their paths as written. ``meta`` carries
        ``scene_name``, ``seed``, ``design`` (None without ``[sample]``) and ``nsample``, and
        with ``[[output]]`` tables, ``outputs`` (them, :mod:`mcchain.ensemble.outputs`).

    Raises:
        SceneError: a bad ``nsample``/``seed`` (for design ``"saltelli"``, a count that is not
            a multiple of the number of varied paths + 2), or a sampled value outside its
            parameter's domain (e.g. a normal mass draw <= 0), naming the path and the sample.
    """
    sample = scene.sample
    if nsample is None:
        nsample = sample.count if sample is not None else 1
        count_name = "sample.count"
    if seed is None:
        seed = sample.seed if sample is not None else 0
    nsample = _check_count(count_name, nsample, 1)
    seed = _check_count("seed", seed, 0, MAX_SEED)
    if sample is not None and sample.design == "saltelli":
        reason = saltelli_count_error(len(sample.vary), nsample)
        if reason is not None:
            raise SceneError(f"{count_name}: {reason}")
    check_memory(scene, nsample, count_name)

    arrays = _base_arrays(scene)
    varied: set[Slot] = set()
    paths = scene.param_paths
    if sample is not None and paths:
        if parameters is None:
            values = sample_parameters(sample, count=nsample, seed=seed)
        else:
            values = np.asarray(parameters, dtype=np.float64)
            if values.shape != (nsample, len(paths)):
                raise ValueError(
                    f"parameters: shape {values.shape}, expected {(nsample, len(paths))}"
                )
        for j, path in enumerate(paths):
            ref = parse_path(scene, path, PARAM_SHAPES)
            column = values[:, j]
            _check_domain(ref, path, column)
            name, idx = parameter_slot(ref)
            arr = arrays[name]
            if arr.shape[0] != nsample:
                arr = arrays[name] = np.repeat(arr, nsample, axis=0)
            where: tuple[slice | int, ...] = (slice(None), *idx)
            arr[where] = column
            varied.add((name, idx))
    else:
        values = np.empty((nsample, 0), dtype=np.float64)
    tables = _time_tables(scene, arrays)
    _derived_defaults(scene, arrays, varied, nsample)

    clearance = PARAMETERS["joint", "clearance"]
    kind = np.array(
        [
            JointKind.PRISMATIC
            if j.type == "prismatic"
            else JointKind.CLEARANCE
            if j.clearance > 0 or clearance.model_index(k, ()) in varied
            else JointKind.IDEAL
            for k, j in enumerate(scene.joint)
        ],
        dtype=np.int64,
    )
    axis = arrays["joint_axis"]
    axis /= np.hypot(axis[..., 0], axis[..., 1])[..., None]  # NaN (revolute) stays NaN
    joint_row, driver_row = constraint_rows(kind, len(scene.driver))
    joint_model = np.array(
        [
            MODEL_CODES[j.resolved_model] if kind[k] == JointKind.CLEARANCE else LINK
            for k, j in enumerate(scene.joint)
        ],
        dtype=np.int64,
    )
    joint_law = np.array(
        [LAW_CODES[j.contact.law] if j.contact is not None else 0 for j in scene.joint],
        dtype=np.int64,
    )
    _contact_stiffness(scene, arrays, nsample)
    index = {name: i for i, name in enumerate(scene.body_names)}
    index[GROUND_NAME] = GROUND
    written = _written_state(scene, paths)
    joint_written = _written_journals(scene, written, joint_model, index)
    joint_contact_start = tuple(
        (j.contact.start or DEFAULT_START[j.resolved_model])
        if j.contact is not None and joint_model[k] != LINK
        else "seated"
        for k, j in enumerate(scene.joint)
    )

    def topo(refs: list[str]) -> np.ndarray:
        return np.array([index[r] for r in refs], dtype=np.int64)

    model = Model(
        body_names=tuple(scene.body_names),
        joint_names=tuple(scene.joint_names),
        driver_names=tuple(scene.driver_names),
        force_names=tuple(scene.force_names),
        spring_names=tuple(scene.spring_names),
        param_paths=tuple(paths),
        parameters=np.ascontiguousarray(values, dtype=np.float64),
        nsample=nsample,
        joint_body_a=topo([j.bodies[0] for j in scene.joint]),
        joint_body_b=topo([j.bodies[1] for j in scene.joint]),
        joint_kind=kind,
        joint_row=joint_row,
        joint_model=joint_model,
        joint_contact_law=joint_law,
        joint_written=joint_written,
        joint_contact_start=joint_contact_start,
        driver_body=topo([GROUND_NAME if d.slides else str(d.body) for d in scene.driver]),
        driver_joint=np.array(
            [scene.joint_names.index(str(d.joint)) if d.slides else -1 for d in scene.driver],
            dtype=np.int64,
        ),
        driver_row=driver_row,
        driver_law=np.array([DRIVER_LAWS[d.law] for d in scene.driver], dtype=np.int64),
        **tables,
        force_body=topo([f.body for f in scene.force]),
        force_law=np.array([LOAD_LAWS[f.law] for f in scene.force], dtype=np.int64),
        spring_body_a=topo([s.bodies[0] for s in scene.spring]),
        spring_body_b=topo([s.bodies[1] for s in scene.spring]),
        meta={
            "scene_name": scene.name,
            "seed": seed,
            "design": sample.design if sample is not None else None,
            "nsample": nsample,
            "written": written,
            **({"outputs": tuple(scene.output)} if scene.output else {}),
        },
        **{k: np.ascontiguousarray(v, dtype=np.float64) for k, v in arrays.items()},
    )
    check_output_windows(scene, model)
    return model


def _written_state(scene: Scene, paths: list[str]) -> dict[str, tuple[bool, ...]]:
    """Per body, whether the scene gives (or samples) each part of its state at t = 0:
    ``position``, ``angle``, ``velocity``, ``angular_velocity``. Assembly warns when it moves
    a written one (:func:`mcchain.solvers.statics.initial_state_warnings`)."""
    keys = ("position", "angle", "velocity", "angular_velocity")
    return {
        key: tuple(
            (key in body.model_fields_set and getattr(body, key) is not None)
            or any(
                p == f"body.{body.name}.{key}" or p.startswith(f"body.{body.name}.{key}[")
                for p in paths
            )
            for body in scene.body
        )
        for key in keys
    }


def _written_journals(
    scene: Scene,
    written: dict[str, tuple[bool, ...]],
    joint_model: np.ndarray,
    index: dict[str, int],
) -> np.ndarray:
    """``Model.joint_written``: per joint, where the scene writes the journal of a clearance
    joint under a contact law (model contact or auto) — 1 off its wall (free, |d| < c, or
    pressed, |d| > c), 2 on it (|δ| ≤ :func:`mcchain.contact.seat_tolerance`) — or 0 (not
    such a joint, or a body of it placed by mcchain). Judged on the scene as written (its
    nominal values, without ``[sample]``): a journal written on its wall stays seated on
    it whatever clearance a sample draws."""
    codes = np.zeros(len(scene.joint), dtype=np.int64)
    nominal: dict[str, np.ndarray] | None = None
    for k, joint in enumerate(scene.joint):
        placed = all(b == GROUND_NAME or written["position"][index[b]] for b in joint.bodies)
        clearance = joint.clearance
        if joint_model[k] == LINK or not placed or not clearance > 0.0:
            continue
        if nominal is None:
            nominal = _base_arrays(scene)
            _unwritten_angles(scene, nominal, index)
        a, b = (index[name] for name in joint.bodies)
        q0 = nominal["q0"]
        d = world_point(q0, b, nominal["joint_point_b"][:, k]) - world_point(
            q0, a, nominal["joint_point_a"][:, k]
        )
        delta = float(np.hypot(d[0, 0], d[0, 1])) - clearance
        codes[k] = 2 if abs(delta) <= seat_tolerance(clearance) else 1
        _check_written_start(joint, delta, clearance)
    return codes


def _check_written_start(joint: Any, delta: float, clearance: float) -> None:
    """Refuse a ``[joint.contact] start`` given with a journal the file writes elsewhere:
    the written state is kept whatever ``start`` says, so a start that names another place
    (seated: on its wall; pressed: δ > 0; centred: d = 0, each within
    :func:`mcchain.contact.seat_tolerance`) contradicts it."""
    start = joint.contact.start
    tolerance = seat_tolerance(clearance)
    if start is None:
        return
    place = "seated" if abs(delta) <= tolerance else "pressed" if delta > 0.0 else "free"
    agrees = {
        "seated": place == "seated",
        "pressed": place == "pressed",
        "centred": abs(delta + clearance) <= tolerance,
    }[start]
    if not agrees:
        raise SceneError(
            f"joint.{joint.name}.contact.start: {start!r} contradicts the journal the file "
            f"writes ({place}, |d| - c = {delta:.6g} m), which is kept as written; remove "
            "start, or the bodies' positions to have the journal placed"
        )


def _items(scene: Scene, kind: str) -> list[Any]:
    """The scene's items of one kind of :data:`~mcchain.parameters.TABLE` (``[scene]`` is one)."""
    return [scene.scene] if kind == "scene" else list(getattr(scene, kind))


def _base_arrays(scene: Scene) -> dict[str, np.ndarray]:
    """The parameter arrays of the scene as written, each with a sample axis of size 1.

    Every row of :data:`~mcchain.parameters.TABLE` copies its key of every item into its
    Model array; an omitted optional key gives the row's ``unset`` value.
    """
    arrays: dict[str, np.ndarray] = {}
    for row in TABLE:
        items = _items(scene, row.kind)
        fields = row.field if isinstance(row.field, tuple) else (row.field,)
        for name in fields:
            if name not in arrays:
                arrays[name] = np.zeros((1, *row.field_shape(len(items))), dtype=np.float64)
        for i, item in enumerate(items):
            value = row.scene_value(item)
            values = np.broadcast_to(np.asarray(row.unset if value is None else value), row.shape)
            for idx in row.elements:
                name, at = row.model_index(i, idx)
                arrays[name][(0, *at)] = values[idx]
    return arrays


def _check_domain(ref: ParamRef, path: str, column: np.ndarray) -> None:
    domain = PARAMETERS[ref.kind, ref.key].domain
    ok = np.isfinite(column)
    if domain is not None:
        ok &= domain.contains(column)
    if not ok.all():
        i = int(np.argmin(ok))
        rule = f"{ref.key} must be {domain.text}" if domain is not None else "not finite"
        raise SceneError(
            f"sample.vary.{quote_key(path)}: sampled value {float(column[i])!r} at sample {i}: "
            f"{rule} (bound the distribution, e.g. with truncnormal)"
        )


def world_point(q0: np.ndarray, body: int, point: np.ndarray) -> np.ndarray:
    """r + A(θ) s for a body (or the point itself on ground); shapes broadcast over samples."""
    if body == GROUND:
        return point
    x, y, th = q0[:, 3 * body], q0[:, 3 * body + 1], q0[:, 3 * body + 2]
    c, s = np.cos(th), np.sin(th)
    return np.stack(
        [x + c * point[:, 0] - s * point[:, 1], y + s * point[:, 0] + c * point[:, 1]], axis=1
    )


def _derived_defaults(
    scene: Scene, arrays: dict[str, np.ndarray], varied: set[Slot], nsample: int
) -> None:
    """Fill defaults that follow other values: the inertia of a body whose sampled mass
    carries it (``scale_inertia``), body angles and positions not written, driver angle0 (the
    body's angle), a prismatic joint's relative angle (as written or placed), spring rest
    length (the distance at the initial positions)."""
    index = {name: i for i, name in enumerate(scene.body_names)}
    index[GROUND_NAME] = GROUND
    for b, body in enumerate(scene.body):
        if body.scale_inertia and ("body_mass", (b,)) in varied:
            inertia = _rows_like(arrays, "body_inertia", nsample)
            inertia[:, b] = body.inertia * arrays["body_mass"][:, b] / body.mass
    _unwritten_angles(scene, arrays, index)
    _place_on_joints(scene, arrays, index)
    q0 = arrays["q0"]

    def body_varied(b: int) -> bool:
        return b != GROUND and any(("q0", (3 * b + k,)) in varied for k in range(3))

    for d, driver in enumerate(scene.driver):
        if driver.law == "table":  # f(0) of its spline, set by _time_tables
            continue
        if driver.slides:
            if driver.displacement0 is None and ("driver_displacement0", (d,)) not in varied:
                found = _axial_displacement(scene, arrays, index, driver.joint)
                target = _rows_like(arrays, "driver_displacement0", len(found))
                target[:, d] = found
            continue
        b = index[str(driver.body)]
        if driver.angle0 is not None:
            continue
        if ("q0", (3 * b + 2,)) in varied:
            if arrays["driver_angle0"].shape[0] != nsample:
                arrays["driver_angle0"] = np.repeat(arrays["driver_angle0"], nsample, axis=0)
            arrays["driver_angle0"][:, d] = q0[:, 3 * b + 2]
        elif ("driver_angle0", (d,)) not in varied:
            arrays["driver_angle0"][:, d] = q0[0, 3 * b + 2]

    for k, joint in enumerate(scene.joint):
        if joint.type != "prismatic" or joint.relative_angle is not None:
            continue
        if ("joint_relative_angle", (k,)) in varied:
            continue
        a, b = index[joint.bodies[0]], index[joint.bodies[1]]
        relative = (q0[:, 3 * b + 2] if b != GROUND else 0.0) - (
            q0[:, 3 * a + 2] if a != GROUND else 0.0
        )
        relative = np.broadcast_to(relative, (q0.shape[0],))
        target = _rows_like(arrays, "joint_relative_angle", q0.shape[0])
        target[:, k] = relative

    for s, spring in enumerate(scene.spring):
        if spring.rest_length is not None or ("spring_rest_length", (s,)) in varied:
            continue
        a, b = index[spring.bodies[0]], index[spring.bodies[1]]
        pa, pb = arrays["spring_point_a"][:, s], arrays["spring_point_b"][:, s]
        wa, wb = world_point(q0, a, pa), world_point(q0, b, pb)
        length = np.hypot(*(wb - wa).T)
        per_sample = (
            body_varied(a)
            or body_varied(b)
            or any(("spring_point_a", (s, k)) in varied for k in range(2))
            or any(("spring_point_b", (s, k)) in varied for k in range(2))
        )
        rest = arrays["spring_rest_length"]
        if per_sample and rest.shape[0] != nsample:
            rest = arrays["spring_rest_length"] = np.repeat(rest, nsample, axis=0)
        rest[:, s] = length if per_sample else length[0]


def _axial_displacement(
    scene: Scene, arrays: dict[str, np.ndarray], index: dict[str, int], joint: str | None
) -> np.ndarray:
    """u·d of a prismatic joint at the initial positions, per row of ``q0``: the displacement
    along its axis u (unit, in its first body's frame) of the second body's point from the
    first's, m."""
    k = scene.joint_names.index(str(joint))
    a, b = (index[name] for name in scene.joint[k].bodies)
    shapes = [arrays[n].shape[0] for n in ("q0", "joint_point_a", "joint_point_b", "joint_axis")]
    rows = max(shapes)
    q0 = np.broadcast_to(arrays["q0"], (rows, arrays["q0"].shape[1]))
    point_a = np.broadcast_to(arrays["joint_point_a"][:, k], (rows, 2))
    point_b = np.broadcast_to(arrays["joint_point_b"][:, k], (rows, 2))
    d = world_point(q0, b, point_b) - world_point(q0, a, point_a)
    u = np.broadcast_to(arrays["joint_axis"][:, k], (rows, 2))
    u = u / np.hypot(u[:, 0], u[:, 1])[:, None]
    theta = q0[:, 3 * a + 2] if a != GROUND else np.zeros(rows)
    c, s = np.cos(theta), np.sin(theta)
    ux, uy = c * u[:, 0] - s * u[:, 1], s * u[:, 0] + c * u[:, 1]
    return np.asarray(ux * d[:, 0] + uy * d[:, 1])


def spline_table(times: list[float], values: list[float]) -> tuple[np.ndarray, np.ndarray]:
    """The cubic spline through (``times``, ``values``) as the kernels evaluate it
    (:func:`mcchain.kernels.tables.spline_at`): knots (n,) and ascending coefficients
    (4 (n − 1),) per segment. Not-a-knot ends (scipy's default: a cubic through the first and
    last four points; with 2 or 3 points the line or parabola through them)."""
    from scipy.interpolate import CubicSpline

    knots = np.asarray(times, dtype=np.float64)
    spline = CubicSpline(knots, np.asarray(values, dtype=np.float64))
    return knots, np.ascontiguousarray(spline.c[::-1].T).reshape(-1)  # (c0, c1, c2, c3) rows


def _time_tables(scene: Scene, arrays: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The splines of table drivers and loads, padded to the longest table (the Model's
    ``driver_table_*``/``force_table_*``); a table driver starts at f(0) with no steady
    rate (its ``angle0``/``displacement0`` and ``omega``/``speed`` columns)."""
    out: dict[str, np.ndarray] = {}
    tables: dict[str, list[tuple[list[float], list[float]] | None]] = {
        "driver": [
            (d.times or [], (d.displacements if d.slides else d.angles) or [])
            if d.law == "table"
            else None
            for d in scene.driver
        ],
        "force": [
            (f.times or [], f.factors or []) if f.law == "table" else None for f in scene.force
        ],
    }
    for kind, written in tables.items():
        fitted = [spline_table(*table) if table is not None else None for table in written]
        width = max((len(f[0]) for f in fitted if f is not None), default=0)
        knots = np.full((len(fitted), width), np.nan)
        coef = np.zeros((len(fitted), 4 * max(width - 1, 0)))
        size = np.zeros(len(fitted), dtype=np.int64)
        for i, found in enumerate(fitted):
            if found is None:
                continue
            size[i] = len(found[0])
            knots[i, : size[i]] = found[0]
            coef[i, : len(found[1])] = found[1]
            if kind == "driver":
                start = spline_value(found[0], found[1], 0.0)
                slider = scene.driver[i].slides
                arrays["driver_displacement0" if slider else "driver_angle0"][:, i] = start
                arrays["driver_speed" if slider else "driver_omega"][:, i] = 0.0
        out |= {f"{kind}_table_size": size, f"{kind}_table_knots": knots}
        out[f"{kind}_table_coef"] = coef
    return out


def spline_value(knots: np.ndarray, coef: np.ndarray, t: float) -> float:
    """The spline of :func:`spline_table` at ``t`` (numpy, for the compiler)."""
    i = int(np.clip(np.searchsorted(knots, t, side="right") - 1, 0, len(knots) - 2))
    c = coef[4 * i : 4 * i + 4]
    tau = t - knots[i]
    return float(c[0] + tau * (c[1] + tau * (c[2] + tau * c[3])))


def _rows_like(arrays: dict[str, np.ndarray], name: str, rows: int) -> np.ndarray:
    """``arrays[name]`` with ``rows`` samples (repeated from 1 when needed)."""
    arr = arrays[name]
    if arr.shape[0] != rows:
        arr = arrays[name] = np.repeat(arr, rows, axis=0)
    return arr


def _unwritten_angles(scene: Scene, arrays: dict[str, np.ndarray], index: dict[str, int]) -> None:
    """A body angle the scene leaves out (NaN): its driver's ``angle0`` when given, else 0."""
    for driver_index, driver in enumerate(scene.driver):
        if driver.slides:
            continue
        b = index[str(driver.body)]
        angle0 = arrays["driver_angle0"][:, driver_index]
        if np.isnan(arrays["q0"][:, 3 * b + 2]).any() and not np.isnan(angle0).any():
            q0 = _rows_like(arrays, "q0", max(arrays["q0"].shape[0], angle0.shape[0]))
            q0[:, 3 * b + 2] = np.where(np.isnan(q0[:, 3 * b + 2]), angle0, q0[:, 3 * b + 2])
    q0 = arrays["q0"]
    angles = q0[:, 2::3]
    angles[np.isnan(angles)] = 0.0


def _place_on_joints(scene: Scene, arrays: dict[str, np.ndarray], index: dict[str, int]) -> None:
    """Positions the scene leaves out (NaN), walked over the joints from ground.

    A body is placed from a neighbour already placed (ground, a body with a written position,
    or one placed before) so that their joint's two points coincide at the body's angle: an
    ideal joint holds, a clearance joint has d = 0 until assembly sets |d| = c. A body no
    joint reaches from a placed one stays at the origin.
    """
    unplaced = {
        b for b in range(len(scene.body)) if np.isnan(arrays["q0"][:, 3 * b : 3 * b + 2]).any()
    }
    if not unplaced:
        return
    point_a, point_b = arrays["joint_point_a"], arrays["joint_point_b"]
    q0 = _rows_like(arrays, "q0", max(arrays["q0"].shape[0], point_a.shape[0], point_b.shape[0]))
    progress = True
    while unplaced and progress:
        progress = False
        for k, joint in enumerate(scene.joint):
            a, b = index[joint.bodies[0]], index[joint.bodies[1]]
            for known, new, known_point, new_point in (
                (a, b, point_a[:, k], point_b[:, k]),
                (b, a, point_b[:, k], point_a[:, k]),
            ):
                if new in unplaced and known not in unplaced:
                    theta = q0[:, 3 * new + 2]
                    c, s = np.cos(theta), np.sin(theta)
                    rotated = np.stack(
                        [c * new_point[:, 0] - s * new_point[:, 1],
                         s * new_point[:, 0] + c * new_point[:, 1]],
                        axis=1,
                    )  # fmt: skip
                    centre = world_point(q0, known, known_point) - rotated
                    written = q0[:, 3 * new : 3 * new + 2]
                    q0[:, 3 * new : 3 * new + 2] = np.where(np.isnan(written), centre, written)
                    unplaced.discard(new)
                    progress = True
    for b in unplaced:
        column = q0[:, 3 * b : 3 * b + 2]
        column[np.isnan(column)] = 0.0


def _contact_stiffness(scene: Scene, arrays: dict[str, np.ndarray], nsample: int) -> None:
    """K of each ``[joint.contact]`` given by radius and materials instead of ``stiffness``:
    internal cylindrical contact (:func:`mcchain.contact.internal_cylinder_stiffness`), per
    sample when the clearance is sampled."""
    for k, joint in enumerate(scene.joint):
        contact = joint.contact
        if contact is None or contact.stiffness is not None:
            continue
        assert contact.radius and contact.youngs_modulus and contact.poisson_ratio is not None
        clearance = arrays["joint_clearance"][:, k]
        stiffness = np.array(
            [
                internal_cylinder_stiffness(
                    contact.radius, float(c), contact.youngs_modulus, contact.poisson_ratio
                )
                for c in clearance
            ]
        )
        target = arrays["joint_contact_stiffness"]
        if clearance.shape[0] != target.shape[0]:
            target = arrays["joint_contact_stiffness"] = np.repeat(target, nsample, axis=0)
        target[:, k] = stiffness
