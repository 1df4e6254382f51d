"""Static analyses: assembly, equilibrium and eigenpulsations for a batch of samples.

Contract:

1. :func:`assemble` projects every sample's initial state onto the constraints (positions
   that already satisfy them are kept bit for bit).
2. :func:`solve_equilibrium` runs Newton on (q, λ) from the assembled positions.
3. :func:`solve_modes` reduces (K, M) to the null space of B and returns the signed
   eigenpulsations p (rad/s, ascending), optionally the mode shapes, and the damped modes
   (the quadratic problem with the dampers' C, :mod:`mcchain.solvers.damped`).
4. Failed samples are NaN with their status bits set; nothing raises for a bad sample.
   :func:`check_scene` raises :class:`~mcchain.errors.SceneError` for a scene whose
   *nominal* instance cannot run at all (redundant constraints, no assembly).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from mcchain.errors import SceneError
from mcchain.kernels import assembly
from mcchain.kernels import statics as kernels
from mcchain.model import JointKind, Model
from mcchain.scene.models import Equilibrium, Scene
from mcchain.solvers.damped import damped_modes
from mcchain.solvers.threads import over_samples
from mcchain.status import STATUS_DTYPE, Status


@dataclass(frozen=True)
class Assembled:
    """Consistent initial states. q, v: (nsample, 3 nbody); status: (nsample,) uint32."""

    q: np.ndarray
    v: np.ndarray
    status: np.ndarray


@dataclass(frozen=True)
class EquilibriumResult:
    """Equilibria of a batch.

    Attributes:
        q: (nsample, 3 nbody) configuration, NaN where failed.
        lam: (nsample, ncon) multipliers; the force body a exerts on body b at joint k is
            −λ_k (ideal) or −λ_k e_k (clearance).
        joint_force: (nsample, njoint, 2) force on body b by body a, N.
        contact_force: (nsample, njoint) λ of clearance joints, NaN for the others, N.
        joint_moment: (nsample, njoint) couple on body b by body a of prismatic joints, NaN
            for revolute ones, N m.
        iterations: (nsample,) Newton iterations to reach the tolerance.
        history: (nsample, max_iterations + 1, 2) per iteration the scaled residual norm
            and the scaled Newton step norm (NaN after the last).
        status: (nsample,) uint32 status bits (including those of assembly).
    """

    q: np.ndarray
    lam: np.ndarray
    joint_force: np.ndarray
    contact_force: np.ndarray
    iterations: np.ndarray
    history: np.ndarray
    status: np.ndarray
    joint_moment: np.ndarray


@dataclass(frozen=True)
class ModesResult:
    """Eigenpulsations of a batch.

    Attributes:
        omega: (nsample, nmode) signed p = sign(p²)√|p²|, rad/s, ascending; NaN where failed.
        shapes: (nsample, nmode, 3 nbody) mass-normalised mode shapes, or None.
        stable: (nsample,) bool, no p² < 0 (False where failed).
        status: (nsample,) uint32 status bits.
        damped_omega: (nsample, nmode) |Im s| of the damped modes, rad/s, or None.
        damping_ratio: (nsample, nmode) ζ of the damped modes (see :mod:`.damped`), or None.
    """

    omega: np.ndarray
    shapes: np.ndarray | None
    stable: np.ndarray
    status: np.ndarray
    damped_omega: np.ndarray | None = None
    damping_ratio: np.ndarray | None = None


def assemble(
    model: Model,
    status: np.ndarray | None = None,
    q_start: np.ndarray | None = None,
    v_start: np.ndarray | None = None,
) -> Assembled:
    """Project every sample's initial positions and velocities onto the constraints (from
    ``q_start``/``v_start`` (nsample or 1, 3 nbody) instead of the model's when given)."""
    nsample = model.nsample
    q0 = model.q0 if q_start is None else q_start
    v0 = model.v0 if v_start is None else v_start
    # C order: a copy of a broadcast view is F-ordered, and numba compiles per layout
    q = np.array(np.broadcast_to(q0, (nsample, model.ndof)), dtype=np.float64, order="C")
    v = np.array(np.broadcast_to(v0, (nsample, model.ndof)), dtype=np.float64, order="C")
    status = _status_or_new(status, nsample)
    over_samples(assembly.assemble_batch, nsample, model.kernel_model(), q, v, status)
    return Assembled(q=q, v=v, status=status)


def solve_equilibrium(
    model: Model,
    q_start: np.ndarray,
    status: np.ndarray | None = None,
    settings: Equilibrium | None = None,
) -> EquilibriumResult:
    """Newton equilibrium of every sample from ``q_start`` (nsample, 3 nbody).

    ``settings`` is the scene's ``[equilibrium]`` section (tolerance, iterations); without
    it, the section's defaults (``Equilibrium()``). Samples whose ``status`` already carries
    a bit are skipped (NaN).
    """
    settings = Equilibrium() if settings is None else settings
    tolerance, max_iterations = settings.tolerance, settings.max_iterations
    nsample = model.nsample
    q = np.array(q_start, dtype=np.float64, copy=True, order="C")
    lam = np.full((nsample, model.ncon), np.nan)
    iterations = np.zeros(nsample, dtype=np.int64)
    history = np.full((nsample, max_iterations + 1, 2), np.nan)
    status = _status_or_new(status, nsample).copy()
    km = model.kernel_model()
    over_samples(
        kernels.equilibrium_batch, nsample,
        km, tolerance, max_iterations, q, lam, iterations, history, status,
    )  # fmt: skip
    joint_force = np.full((nsample, model.njoint, 2), np.nan)
    contact_force = np.full((nsample, model.njoint), np.nan)
    over_samples(kernels.joint_forces_batch, nsample, km, q, lam, joint_force, contact_force)
    prismatic = model.joint_kind == JointKind.PRISMATIC
    moment = np.full_like(contact_force, np.nan)  # the kernel's slot of a prismatic couple
    moment[:, prismatic] = contact_force[:, prismatic]
    contact_force[:, prismatic] = np.nan
    return EquilibriumResult(
        q, lam, joint_force, contact_force, iterations, history, status, moment
    )


def solve_modes(
    model: Model, equilibrium: EquilibriumResult, shapes: bool = False, damped: bool = False
) -> ModesResult:
    """Eigenpulsations about each sample's equilibrium (the paper's linear vibrations); the
    mode shapes if ``shapes``; the damped modes if ``damped`` (equal to the undamped ones
    for a scene without dampers, springs with ``damping``)."""
    nsample = model.nsample
    omega = np.full((nsample, model.nmode), np.nan)
    has_dampers = damped and bool(np.any(model.spring_damping))
    want_shapes = shapes or has_dampers  # the damped problem is posed in the modal basis
    shape_rows = nsample if want_shapes else 1
    shape_array = np.full((shape_rows, model.nmode, model.ndof), np.nan)
    status = equilibrium.status.copy()
    km = model.kernel_model()
    q = np.ascontiguousarray(equilibrium.q)
    lam = np.ascontiguousarray(equilibrium.lam)
    over_samples(kernels.modes_batch, nsample, km, q, lam, want_shapes, omega, shape_array, status)
    stable = (status & (Status.UNSTABLE_EQUILIBRIUM | _FAILED)) == 0
    modal_damping = None
    if has_dampers:
        modal_damping = np.full((nsample, model.nmode, model.nmode), np.nan)
        over_samples(kernels.modal_damping_batch, nsample, km, q, shape_array, modal_damping)
    result = ModesResult(omega, shape_array if shapes else None, stable, status)
    if not damped:
        return result
    roots = damped_modes(omega, modal_damping)
    return replace(result, damped_omega=roots.damped_omega, damping_ratio=roots.damping_ratio)


_FAILED = Status.ASSEMBLY_FAILED | Status.EQUILIBRIUM_NOT_CONVERGED | Status.SINGULAR


@dataclass(frozen=True)
class CycleModes:
    """Modes of frozen configurations along one turn of a driver.

    Attributes:
        phase: (points,) the driver's angle from its ``angle0``, rad: 2π j / points.
        omega: (nsample, points, nmode) signed pulsations, rad/s, ascending; NaN where the
            configuration could not be assembled or its B lost rank.
        q, v: (nsample, points, 3 nbody) the configurations and their velocities; lam:
            (nsample, points, ncon) their multipliers (inverse dynamics at the driver's speed).
    """

    phase: np.ndarray
    omega: np.ndarray
    q: np.ndarray
    v: np.ndarray
    lam: np.ndarray


def solve_modes_along(
    model: Model, driver: int, points: int, q_start: np.ndarray, v_start: np.ndarray
) -> CycleModes:
    """The modes of the mechanism frozen at ``points`` equally spaced angles of one turn of
    driver ``driver`` (a designer's check of natural frequencies against the drive speed).

    Each configuration is assembled kinematically with the driver at angle0 + 2π j/points
    (from the previous configuration, so the branch is kept), clearance journals pressed on
    their bearings as the ideal-joint force says, velocities from the drivers with journals
    at rest; λ comes from the KKT system at those velocities (inverse dynamics: inertia
    loads included), and the modes from the stiffness at (q, λ) with the drivers held, as
    ``[modes]`` does at the equilibrium. Nothing here changes a sample's status.
    """
    nsample, nmode = model.nsample, model.nmode
    phase = 2.0 * np.pi * np.arange(points) / points
    omega = np.full((nsample, points, nmode), np.nan)
    qs = np.full((nsample, points, model.ndof), np.nan)
    vs = np.full((nsample, points, model.ndof), np.nan)
    lams = np.full((nsample, points, model.ncon), np.nan)
    angle0 = np.broadcast_to(model.driver_angle0, (nsample, model.ndriver)).copy()
    free = np.full_like(np.broadcast_to(model.joint_eccentricity, (1, model.njoint)), np.nan)
    q, v = q_start, v_start
    shapes = np.zeros((1, nmode, model.ndof))
    for j, turn in enumerate(phase):
        angles = angle0.copy()
        angles[:, driver] += turn
        # every clearance journal seated (joint_written 0: none kept off its wall)
        frozen = replace(
            model, driver_angle0=angles, joint_eccentricity=free,
            joint_written=np.zeros_like(model.joint_written),
        )  # fmt: skip
        status = np.zeros(nsample, dtype=STATUS_DTYPE)
        assembled = assemble(frozen, status, q, v)
        km = frozen.kernel_model()
        lam = np.full((nsample, model.ncon), np.nan)
        over_samples(
            kernels.dynamic_multipliers_batch, nsample, km, assembled.q, assembled.v, lam, status
        )
        pulsations = np.full((nsample, nmode), np.nan)  # C-contiguous: one compiled layout
        over_samples(
            kernels.modes_batch, nsample, km, assembled.q, lam, False, pulsations, shapes, status
        )
        omega[:, j], qs[:, j], vs[:, j], lams[:, j] = pulsations, assembled.q, assembled.v, lam
        # the next configuration starts from this one where it was found
        q = np.where(np.isfinite(assembled.q), assembled.q, q)
        v = np.where(np.isfinite(assembled.v), assembled.v, v)
    return CycleModes(phase, omega, qs, vs, lams)


def check_scene(model: Model) -> Assembled:
    """Raise :class:`SceneError` if the nominal instance (sample 0) cannot be assembled or
    has redundant constraints; return its assembled state otherwise.

    The degrees of freedom are 3 nbody − ncon; they must be ≥ 0 and B must have full row
    rank at the assembled configuration.
    """
    nominal = model.select(0, 1)
    # freedoms the joints leave, clearances closed (a clearance adds play, not a freedom)
    free = nominal.ndof - 2 * nominal.njoint
    if nominal.ndriver > max(free, 0) and free >= 0:
        extra = nominal.driver_names[free]
        already = ", ".join(f"driver.{d}" for d in nominal.driver_names[:free])
        raise SceneError(
            f"driver.{extra}: the mechanism has {free} degree(s) of freedom ({nominal.ndof} "
            f"coordinates, {nominal.njoint} joints of 2 rows each, clearances closed)"
            + (f", already driven by {already}" if already else "")
            + "; one more driver over-constrains it (drive one body per freedom)"
        )
    dof = nominal.ndof - nominal.ncon
    if dof < 0:
        raise SceneError(
            f"joint: negative degrees of freedom: {nominal.ncon} constraint rows for "
            f"{nominal.ndof} coordinates ({nominal.nbody} bodies)"
        )
    assembled = assemble(nominal)
    bits = int(assembled.status[0])
    if bits & Status.ASSEMBLY_FAILED:
        raise SceneError(
            "body: initial positions cannot be assembled: no configuration near them "
            "satisfies the joints and drivers (check joint points and body positions)"
        )
    # a journal written off its wall under a contact law is not a constraint at the start
    rows = np.ones(nominal.ncon, dtype=bool)
    rows[nominal.joint_row[np.asarray(nominal.joint_written) == 1]] = False
    rank = constraint_rank(nominal, assembled.q[0], rows=rows)
    if bits & Status.SINGULAR or rank < int(rows.sum()):
        raise SceneError(
            f"joint: redundant constraints: rank of B is {rank} < {int(rows.sum())} constraint "
            "rows at the initial configuration (a joint or driver repeats another's constraint)"
        )
    return assembled


def _point_offsets(model: Model, body: int) -> np.ndarray:
    """(npoint, 2) local points of a body that matter for its placement: its centre and the
    points of its joints, m (sample 0)."""
    points = [np.zeros(2)]
    for k in range(model.njoint):
        if int(model.joint_body_a[k]) == body:
            points.append(model.joint_point_a[0, k])
        if int(model.joint_body_b[k]) == body:
            points.append(model.joint_point_b[0, k])
    return np.array(points)


def _rotated(theta: float, points: np.ndarray) -> np.ndarray:
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([c * points[:, 0] - s * points[:, 1], s * points[:, 0] + c * points[:, 1]], 1)


def written_state(scene: Scene) -> tuple[Model, Assembled]:
    """The scene as written (without ``[sample]``) compiled, and its assembled state: what
    :func:`initial_state_warnings` compares."""
    from mcchain.scene.compile import compile_model

    written = compile_model(scene.model_copy(update={"sample": None}))
    return written, assemble(written)


def initial_state_warnings(model: Model, assembled: Assembled) -> list[str]:
    """One line per body whose *written* state at t = 0 assembly changed noticeably.

    Sample 0 of ``model`` (compile the scene without ``[sample]`` for the state as written)
    is compared with its assembled state. A body's move is the largest displacement of its
    centre and its joint points; it is reported when the scene wrote (or sampled) the body's
    position (an angle written alone is a hint that picks the branch) and the move exceeds
    1e-12 of the mechanism's size (assembly's tolerance: whatever its size relative to the
    clearances, a journal moved onto its wall is a move). Velocities the
    scene wrote are reported when the largest change of those points' velocities exceeds
    1e-6 of the velocity scale (written speeds, driver speeds × size). Bodies whose state
    the scene leaves out are placed and analysed silently: that is what they ask for.
    """
    written = model.meta.get("written")
    if not isinstance(written, dict) or assembled.status[0] != 0:
        return []
    q0 = np.broadcast_to(model.q0, (model.nsample, model.ndof))[0]
    v0 = np.broadcast_to(model.v0, (model.nsample, model.ndof))[0]
    q, v = assembled.q[0], assembled.v[0]
    size = max(
        (float(np.hypot(*p)) for p in (*model.joint_point_a[0], *model.joint_point_b[0])),
        default=1.0,
    )
    size = size if size > 0 else 1.0
    position_tol = 1e-12 * size
    speeds = [
        np.abs(v0).max(initial=0.0) * size,
        np.abs(model.driver_omega[0]).max(initial=0.0) * size,
    ]
    velocity_tol = 1e-6 * max(*speeds, 1e-9)
    lines = []
    for b, name in enumerate(model.body_names):
        points = _point_offsets(model, b)
        if written["position"][b]:  # an angle alone is a rough hint: it picks the branch
            before = q0[3 * b : 3 * b + 2] + _rotated(q0[3 * b + 2], points)
            after = q[3 * b : 3 * b + 2] + _rotated(q[3 * b + 2], points)
            move = float(np.hypot(*(after - before).T).max())
            centre = float(np.hypot(*(after[0] - before[0])))
            if move > position_tol:
                lines.append(
                    f"body.{name}: assembly moved it by {move:.3g} m from its written state "
                    f"(centre {centre:.3g} m, "
                    f"angle {float(q[3 * b + 2] - q0[3 * b + 2]):+.3g} rad) to close its joints "
                    "and drivers; check its position, angle and joint points"
                )
        if written["velocity"][b] or written["angular_velocity"][b]:
            arms = _rotated(q[3 * b + 2], points)

            def point_velocities(
                state: np.ndarray, b: int = b, arms: np.ndarray = arms
            ) -> np.ndarray:
                x, y, w = state[3 * b : 3 * b + 3]
                return np.stack([x - w * arms[:, 1], y + w * arms[:, 0]], 1)

            change = float(np.hypot(*(point_velocities(v) - point_velocities(v0)).T).max())
            if change > velocity_tol:
                lines.append(
                    f"body.{name}: assembly changed its written velocity by {change:.3g} m/s "
                    f"(angular velocity {float(v[3 * b + 2] - v0[3 * b + 2]):+.3g} rad/s) to "
                    "agree with the joints and drivers"
                )
    return lines


def start_multipliers(
    model: Model,
    q: np.ndarray,
    v: np.ndarray,
    sample: int = 0,
    law: np.ndarray | None = None,
) -> np.ndarray:
    """λ (ncon,) of M q̈ + Bᵀλ = F, B q̈ = γ at t = 0 for one sample's state q, v (3 nbody,):
    a clearance joint's λ > 0 means its journal presses on the bearing (contact holds).

    ``law`` (njoint,) bool: the clearance joints under the contact law at t = 0. Their rows
    leave the system; the law's force F_n = K max(δ, 0)^m (undamped: a contact present at
    t = 0 has no onset) acts instead, −F_n n on the journal and +F_n n on the bearing, and is
    their λ (N)."""
    from mcchain.kernels.forces import applied_forces, mass_diagonal
    from mcchain.kernels.joints import constraint_gamma, constraint_jacobian, joint_vectors

    km = model.kernel_model()
    q = np.ascontiguousarray(q, dtype=np.float64)
    v = np.ascontiguousarray(v, dtype=np.float64)
    n, m = model.ndof, model.ncon
    B, gamma, F, mass = np.zeros((m, n)), np.zeros(m), np.zeros(n), np.zeros(n)
    constraint_jacobian(km, sample, q, B)
    constraint_gamma(km, sample, q, v, 0.0, gamma)
    applied_forces(km, sample, q, v, 0.0, F)
    mass_diagonal(km, sample, mass)
    rows = np.ones(m, bool)
    normal = np.zeros(model.njoint)
    for k in np.flatnonzero(law) if law is not None else ():
        r = int(model.joint_row[k])
        rows[r] = False
        pax, pay, pbx, pby, dx, dy = joint_vectors(km, sample, q, int(k))
        rho = float(np.hypot(dx, dy))
        ix = sample % model.joint_clearance.shape[0]
        delta = rho - float(model.joint_clearance[ix, k])
        stiffness = np.broadcast_to(model.joint_contact_stiffness, (sample + 1, model.njoint))
        expo = np.broadcast_to(model.joint_contact_exponent, (sample + 1, model.njoint))
        normal[k] = float(stiffness[sample, k]) * max(delta, 0.0) ** float(expo[sample, k])
        fx, fy = -normal[k] * dx / rho, -normal[k] * dy / rho  # on the journal
        for body, sign, px, py in ((model.joint_body_b[k], 1.0, pbx, pby),
                                   (model.joint_body_a[k], -1.0, pax, pay)):  # fmt: skip
            if body >= 0:
                F[3 * body : 3 * body + 3] += sign * np.array([fx, fy, px * fy - py * fx])
    Bk = B[rows]
    mk = int(rows.sum())
    kkt = np.block([[np.diag(mass), Bk.T], [Bk, np.zeros((mk, mk))]])
    lam = np.zeros(m)
    lam[rows] = np.linalg.solve(kkt, np.concatenate([F, gamma[rows]]))[n:]
    lam[~rows] = normal[[k for k in range(model.njoint) if law is not None and law[k]]]
    return lam


def constraint_rank(
    model: Model, q: np.ndarray, sample: int = 0, rows: np.ndarray | None = None
) -> int:
    """Numerical rank of B at q (3 nbody,) for one sample, by the kernels' QR test (of the
    rows ``rows`` (ncon,) bool only, when given)."""
    from mcchain.kernels.joints import constraint_jacobian
    from mcchain.kernels.linalg import null_space

    km = model.kernel_model()
    B = np.zeros((model.ncon, model.ndof))
    constraint_jacobian(km, sample, np.ascontiguousarray(q, dtype=np.float64), B)
    if rows is not None:
        B = np.ascontiguousarray(B[rows])
    m = B.shape[0]
    Q = np.empty((model.ndof, model.ndof))
    work = np.empty((model.ndof, m + 1))
    return int(null_space(B, m, model.ndof, kernels.RANK_RTOL, Q, work))


def describe_constraints(model: Model) -> list[tuple[str, str, int, int]]:
    """(name, kind, first row, rows) of every joint and driver, for ``mcchain validate``."""
    rows = []
    for k, name in enumerate(model.joint_names):
        kind = JointKind(int(model.joint_kind[k]))
        text = {
            JointKind.IDEAL: "ideal revolute",
            JointKind.CLEARANCE: "clearance revolute",
            JointKind.PRISMATIC: "prismatic",
        }[kind]
        rows.append((name, text, int(model.joint_row[k]), kind.rows))
    for j, name in enumerate(model.driver_names):
        rows.append((name, "driver", int(model.driver_row[j]), 1))
    return rows


def _status_or_new(status: np.ndarray | None, nsample: int) -> np.ndarray:
    if status is None:
        return np.zeros(nsample, dtype=STATUS_DTYPE)
    return np.ascontiguousarray(status, dtype=STATUS_DTYPE)
