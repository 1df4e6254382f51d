"""Time histories of a batch of samples: the paper's nonlinear vibrations (§2.1).

Contract of :func:`simulate`:

1. Equations: M q̈ + Bᵀλ = F(q, q̇, t), Φ(q, t) = 0, with M diagonal, in
   absolute coordinates. Index-1 methods solve B q̈ = γ − 2αΦ̇ − β²Φ (Baumgarte, α and β
   from ``[simulate] baumgarte``) through the Schur complement S = B M⁻¹ Bᵀ; the index-3
   method (generalized-α) solves Φ(q) = 0 itself by Newton on the KKT system.
2. Methods are the rows of :data:`METHODS`; all share the start state, the output times
   (:func:`.grid.output_times`: k · ``output_dt``, then t_end itself as the last) and the
   outputs below. Fixed-step methods need ``output_dt`` to be a whole multiple of ``dt`` and step
   with ``dt`` as written, except a last step shortened to land on t_end; adaptive ones
   land exactly on every output time.
3. Start: the model's ``q0``/``v0`` (assembled by statics) or the arrays passed as
   ``q_start``/``v_start`` (e.g. the equilibrium with zero velocity); ``perturb`` adds to
   named coordinates, and the other coordinates are then projected back onto the position
   and velocity constraints (the perturbed ones held fixed), so "the equilibrium plus 0.1 rad
   on the bar" is a consistent start. Each contact-law joint starts in the mode its journal's
   place says (:func:`.start.start_modes`: the law when free or pressed, seated on the wall,
   or the link for model auto on the wall), the same for every method.
4. Outputs at ``time`` (ntime,): ``q``, ``v`` (sample, time, body, dof); ``joint_force``
   (sample, time, joint, xy) = force on body b by body a (−λ ideal, −λ e clearance);
   ``contact_force`` (sample, time, joint) = λ of clearance joints (NaN for ideal ones);
   ``driver_torque`` (sample, time, driver) = −λ of the driver row (``driver_force`` for a
   slider driver: the force along its joint's axis, N); ``constraint_error``
   (sample, time) = max |Φ|; ``energy`` (sample, time) = kinetic + potential (gravity, springs,
   constant forces −f·r, couples −τθ; drivers do work, so it is not conserved with them) +
   the elastic energy K δ^(m+1)/(m+1) of contacts under a contact law. Per sample, the
   continuous peaks over the run (tracked at every step, located within the step: not from
   the stored points): ``peak_joint_force`` (sample, joint) of |joint_force|,
   ``peak_driver_torque`` (sample, driver) of |driver_torque| (``peak_driver_force`` for a
   slider driver), and with contact-law joints ``peak_contact_force``.
5. Status (per sample, :mod:`mcchain.status`): DIVERGED when the state is non-finite or
   max |Φ| exceeds ``constraint_tolerance`` (or an implicit/adaptive step fails), SINGULAR
   when S (or the KKT matrix) loses rank — a pivot ≤ ``SINGULAR_PIVOT`` × its diagonal —
   except on the robust path (``rk4-projection``), which drops the dependent rows and goes
   on; both are failures: the values from that time on are NaN, and ``diverged_time`` /
   ``singular_time`` say when (a rank loss inside an RK4 step is reported at the step's
   end). CONTACT_LOST (a warning) when λ ≤ 0 at a clearance joint at the start of a step
   (every accepted step for rk45, every output time for radau), with ``contact_lost_time``.
   Nothing raises for a bad sample.
6. Deterministic: a sample's history is bit-identical whatever the chunk of samples it is
   run in and the numba thread count (no reduction across samples).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from mcchain.contact import CONTACT_SUMMARY
from mcchain.model import JointKind, Model
from mcchain.scene.loading import load_section
from mcchain.scene.models import Simulate
from mcchain.solvers.grid import output_times
from mcchain.solvers.history_rows import ROWS_BLOCK, float64_rows, store_rows
from mcchain.solvers.kernel_choice import choose_kernels
from mcchain.solvers.start import start_modes, start_state
from mcchain.solvers.threads import on_every_thread, over_samples
from mcchain.status import FAILURE_BITS

SINGULAR_PIVOT = 1e-8
"""Relative LDLᵀ pivot of S below which the constraints count as rank-deficient."""

PROJECTION_TOLERANCE = 1e-13
"""max |Φ| (m, rad) at which the projection of ``rk4-projection`` stops iterating."""

ADAPTIVE_MIN_STEP = 1e-12
"""Smallest step of ``rk45`` relative to t_end; below it the sample counts as diverged."""

ADAPTIVE_MAX_STEPS = 10_000_000
"""Step attempts of ``rk45`` per sample before it counts as diverged."""


@dataclass(frozen=True)
class Method:
    """One row of :data:`METHODS`."""

    name: str
    run: Callable[..., None]
    description: str


# ---------------------------------------------------------------------------------------------
# Output arrays


def _allocate(model: Model, ntime: int, dtype: Any) -> dict[str, np.ndarray]:
    n = model.nsample

    def full(*shape: int) -> np.ndarray:
        return np.full(shape, np.nan, dtype=dtype)

    return {
        "q": full(n, ntime, model.nbody, 3),
        "v": full(n, ntime, model.nbody, 3),
        "joint_force": full(n, ntime, model.njoint, 2),
        "contact_force": full(n, ntime, model.njoint),
        "driver_torque": full(n, ntime, model.ndriver),
        "constraint_error": full(n, ntime),
        "energy": full(n, ntime),
    }


def _flat_outputs(out: dict[str, np.ndarray]) -> tuple[np.ndarray, ...]:
    """Views of the history arrays in the layout the kernels write: (sample, time, k)."""
    n, ntime, nbody = out["q"].shape[:3]
    return (
        out["q"].reshape(n, ntime, 3 * nbody),
        out["v"].reshape(n, ntime, 3 * nbody),
        out["joint_force"].reshape(n, ntime, 2 * out["joint_force"].shape[2]),
        out["contact_force"],
        out["driver_torque"],
        out["constraint_error"],
        out["energy"],
    )


# ---------------------------------------------------------------------------------------------
# Method runners: (model, settings, q, v, time, every, out, status, times) -> None


@dataclass
class _Run:
    model: Model
    settings: Simulate
    q: np.ndarray  # (nsample, ndof) start
    v: np.ndarray
    time: np.ndarray
    every: int
    dt: float  # the step of fixed-step methods as written (OutputGrid.dt)
    nstep: int  # their steps to t_end and the last one's length (OutputGrid)
    last_step: float
    out: dict[str, np.ndarray]
    status: np.ndarray
    t_div: np.ndarray
    t_sing: np.ndarray
    t_cl: np.ndarray
    steps: np.ndarray  # (nsample,) int64 diagnostics, see simulate()
    rejected_steps: np.ndarray
    evaluations: np.ndarray
    lanes: int | None = None  # None: the lane kernels' row length (set by _lane_setup)
    # Contact-law joints (lane kernels' extra outputs): per output time δ and the mode of
    # each (sample, time, 2 ncj); per sample the summaries (sample, 5 ncj), see
    # mcchain.codegen.generate.CONTACT_SUMMARY. Empty without such joints.
    contact_history: np.ndarray | None = None
    contact_summary: np.ndarray | None = None
    # Continuous peaks per sample (sample, njoint + ndriver): |joint force| of each joint, then
    # |λ| of each driver (mcchain.kernels.peaks), every method; NaN for a failed sample.
    peaks: np.ndarray | None = None
    # [[output]]s (mcchain.solvers.output_plan.OutputPlan; an empty one without) and their
    # values (sample, nout), every method.
    plan: Any = None
    output_values: np.ndarray | None = None

    @property
    def stored(self) -> int:
        """The output times the history arrays hold: all of ``time``, or 0 (``histories``
        off: the kernels store nothing, every per-sample value is the same)."""
        return int(self.out["energy"].shape[1])

    @property
    def groups(self) -> int:
        """Lane groups of the lane kernels: ``lanes`` samples each, the last one short."""
        assert self.lanes is not None, "the lane kernels set the lane count"
        return -(-self.model.nsample // self.lanes)

    def output_args(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The ``[[output]]`` arrays the loop kernels take: spec, data and the values."""
        assert self.plan is not None and self.output_values is not None
        return self.plan.spec, np.ascontiguousarray(self.plan.data), self.output_values

    def lane_output_args(self) -> tuple[np.ndarray, ...]:
        """The ``[[output]]`` arrays the lane kernels take after the peaks (none without)."""
        return self.output_args()[1:] if self.plan is not None and self.plan.names else ()

    def contact_args(self) -> tuple[np.ndarray, ...]:
        """The contact arrays the lane kernels take after the histories (none without)."""
        if self.contact_history is None or self.contact_summary is None:
            return ()
        return (self.contact_history, self.contact_summary)


def _lane_setup(run: _Run, variant: str) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray]:
    """The lane kernels of ``variant`` (see ``mcchain.codegen.generate.VARIANTS``), the packed
    parameters and the start state as (ndof, nsample) columns."""
    from mcchain.codegen.generate import lane_kernels, lane_rows
    from mcchain.codegen.topology import Topology, pack_parameters

    topo = Topology.from_model(run.model)
    outputs = run.plan.signature if run.plan is not None else ()
    rows = lane_rows(topo, variant, outputs)
    if run.lanes is not None and not 1 <= run.lanes <= rows:
        raise ValueError(
            f"lanes: must be in 1..{rows} (the lane kernels' work rows), got {run.lanes}"
        )
    run.lanes = rows if run.lanes is None else run.lanes
    module = lane_kernels(topo, variant, outputs)
    P = pack_parameters(run.model, topo)
    Q0 = np.ascontiguousarray(run.q.T)
    V0 = np.ascontiguousarray(run.v.T)
    return module, P, Q0, V0


def _run_erk(run: _Run, project: bool) -> None:
    from mcchain.kernels.tableaux import RK4

    module, P, Q0, V0 = _lane_setup(run, "rk4-projection" if project else "rk4")
    s = run.settings
    alpha, beta = (0.0, 0.0) if project else s.gains
    nstep = run.nstep
    # Every lane runs every step (a failed one with NaN, in lockstep): stages per step, and
    # stage 0 once more at the end for the last outputs.
    integrated = (run.status & FAILURE_BITS) == 0
    run.steps[integrated] = nstep
    run.evaluations[integrated] = RK4.nstage * nstep + 1
    # One queue of lane groups for every thread: a thread takes the next group when it is
    # done with one, so none waits on another's last block of groups (benchmarks/bench_queue.py).
    queue = np.array([0], dtype=np.int64)
    on_every_thread(
        module.erk_project_run if project else module.erk_run, run.groups,
        P, Q0, V0, run.time, run.dt, run.last_step, nstep, run.every, RK4.A, RK4.b, RK4.c,
        2.0 * alpha, beta * beta, s.constraint_tolerance, SINGULAR_PIVOT,
        project, project, PROJECTION_TOLERANCE, s.max_newton, run.lanes,
        *_flat_outputs(run.out), *run.contact_args(),
        run.peaks, *run.lane_output_args(), run.status, run.t_div, run.t_sing, run.t_cl,
        queue,
    )  # fmt: skip


def _run_rk4(run: _Run) -> None:
    if run.settings.kernels == "loop":
        _run_rk4_loop(run)
    else:
        _run_erk(run, project=False)


def _run_rk4_loop(run: _Run) -> None:
    """RK4 on the generic kernels (:mod:`mcchain.kernels.explicit`): compiled once for every
    topology, the lanes' steps and checks, one sample at a time."""
    from mcchain.kernels.explicit import rk4_run
    from mcchain.kernels.tableaux import RK4

    s = run.settings
    alpha, beta = s.gains
    nstep = run.nstep
    integrated = (run.status & FAILURE_BITS) == 0
    run.steps[integrated] = nstep
    run.evaluations[integrated] = RK4.nstage * nstep + 1
    _over_loop_samples(
        run, rk4_run,
        (run.model.kernel_model(), np.ascontiguousarray(run.q), np.ascontiguousarray(run.v),
         run.time, run.dt, run.last_step, nstep, run.every, run.model.ncon,
         *run.model.constraint_pattern(), RK4.A, RK4.b, RK4.c,
         2.0 * alpha, beta * beta, s.constraint_tolerance, SINGULAR_PIVOT),
        (*_loop_contact_args(run), run.peaks, *run.output_args(), run.status, run.t_div,
         run.t_sing, run.t_cl),
    )  # fmt: skip


def _over_loop_samples(
    run: _Run, kernel: Any, before: tuple[Any, ...], after: tuple[Any, ...]
) -> None:
    """``kernel(start, stop, *before, row0, *histories, *after)`` over the samples, on
    threads: the loop kernels take float64 histories only (``row0`` their first sample), so
    float32 ones are written a block at a time into float64 rows and stored
    (:mod:`.history_rows`)."""
    flat = _flat_outputs(run.out)
    n = run.model.nsample
    if all(a.dtype == np.float64 for a in flat):
        over_samples(kernel, n, *before, 0, *flat, *after, min_block=1)
        return

    def block(start: int, stop: int) -> None:
        rows = float64_rows(flat, start, stop)
        kernel(start, stop, *before, start, *rows, *after)
        store_rows(flat, start, rows)

    over_samples(block, n, min_block=1, max_block=ROWS_BLOCK)


def _loop_contact_args(run: _Run) -> tuple[np.ndarray, np.ndarray]:
    """The contact arrays of the loop kernels: :meth:`_Run.contact_args`, or empty ones of the
    same dimensions for a model without contact-law joints (one compiled signature)."""
    if run.contact_history is None or run.contact_summary is None:
        n = run.model.nsample
        return np.zeros((n, run.stored, 0)), np.zeros((n, 0))
    return run.contact_history, run.contact_summary


def _run_rk4_projection(run: _Run) -> None:
    _run_erk(run, project=True)


def _run_rk45(run: _Run) -> None:
    from mcchain.kernels.tableaux import DOPRI5

    module, P, Q0, V0 = _lane_setup(run, "rk45")
    s = run.settings
    alpha, beta = s.gains
    # One queue of samples for every thread: a lane whose sample is finished takes the next
    # (samples of unequal lengths share the lanes), no thread waits on another's last block,
    # and the lanes drain once, at the end (benchmarks/bench_queue.py).
    queue = np.array([0], dtype=np.int64)
    on_every_thread(
        module.adaptive_run, run.groups,
        P, Q0, V0, 0.0, run.time, min(s.dt, s.output_step), DOPRI5.A, DOPRI5.b, DOPRI5.b_error,
        DOPRI5.c, float(DOPRI5.error_order or 4), s.rtol, s.atol, ADAPTIVE_MIN_STEP * s.t_end,
        ADAPTIVE_MAX_STEPS, 2.0 * alpha, beta * beta, s.constraint_tolerance, SINGULAR_PIVOT,
        run.lanes, *_flat_outputs(run.out),
        *run.contact_args(), run.peaks, *run.lane_output_args(), run.status, run.t_div,
        run.t_sing, run.t_cl, run.steps, run.rejected_steps, run.evaluations, queue,
    )  # fmt: skip


def _run_radau(run: _Run) -> None:
    """Radau IIA(5) on the index-1 equations, one sample at a time (the slow reference), in
    segments between located events where there are contact-law joints
    (:mod:`.radau`)."""
    from mcchain.solvers.radau import run_radau

    run_radau(run, _flat_outputs(run.out), SINGULAR_PIVOT)


def _run_generalized_alpha(run: _Run) -> None:
    from mcchain.kernels.implicit import generalized_alpha_run
    from mcchain.kernels.tableaux import GeneralizedAlpha

    s = run.settings
    coef = GeneralizedAlpha.from_rho(s.rho_inf)
    km = run.model.kernel_model()
    _over_loop_samples(
        run, generalized_alpha_run,
        (km, np.ascontiguousarray(run.q), np.ascontiguousarray(run.v), run.time, run.dt,
         run.last_step, run.nstep, run.every, run.model.ncon, *run.model.constraint_pattern(),
         coef.alpha_m, coef.alpha_f, coef.gamma, coef.beta, s.constraint_tolerance,
         SINGULAR_PIVOT, s.max_newton),
        (*_loop_contact_args(run), run.peaks, *run.output_args(), run.status, run.t_div,
         run.t_sing, run.t_cl, run.steps, run.evaluations),
    )  # fmt: skip


def _prismatic_moments(model: Model, contact_force: np.ndarray) -> dict[str, np.ndarray]:
    """``joint_moment`` (..., njoint): the couple of each prismatic joint, which the kernels
    leave in ``contact_force``'s slot (NaN there afterwards); NaN for revolute joints."""
    prismatic = model.joint_kind == JointKind.PRISMATIC
    moment = np.full_like(contact_force, np.nan)
    moment[..., prismatic] = contact_force[..., prismatic]
    contact_force[..., prismatic] = np.nan
    return {"joint_moment": moment}


def _slider_forces(model: Model, driver_torque: np.ndarray) -> dict[str, np.ndarray]:
    """``driver_force`` (..., ndriver): −λ of slider drivers, the force along the joint's axis
    that the kernels leave in ``driver_torque``'s slot (NaN there afterwards); NaN for drivers
    of an angle."""
    slider = np.asarray(model.driver_joint) >= 0
    force = np.full_like(driver_torque, np.nan)
    force[..., slider] = driver_torque[..., slider]
    driver_torque[..., slider] = np.nan
    return {"driver_force": force}


def _peak_outputs(model: Model, peaks: np.ndarray) -> dict[str, np.ndarray]:
    """``peak_joint_force`` (sample, joint) and ``peak_driver_torque`` (sample, driver), the
    continuous peaks of |joint_force| and |driver_torque| the kernels tracked at every step
    (a slider driver's force is moved to ``peak_driver_force`` afterwards)."""
    nj = model.njoint
    return {
        "peak_joint_force": np.ascontiguousarray(peaks[:, :nj]),
        "peak_driver_torque": np.ascontiguousarray(peaks[:, nj:]),
    }


def _contact_outputs(run: _Run, history_dtype: Any) -> dict[str, np.ndarray]:
    """The contact-law outputs by ensemble variable, every joint (the others: NaN, or -1
    for the integer ones), from the lane kernels' contact arrays."""
    model, n, ntime = run.model, run.model.nsample, run.stored
    assert run.contact_history is not None and run.contact_summary is not None
    joints = np.flatnonzero(model.joint_model)
    pen = np.full((n, ntime, model.njoint), np.nan, dtype=history_dtype)
    mode = np.full((n, ntime, model.njoint), -1, dtype=np.int8)
    hist = run.contact_history.reshape(n, ntime, len(joints), 2)
    pen[:, :, joints] = hist[..., 0]
    mode[:, :, joints] = np.where(np.isnan(hist[..., 0]), -1, hist[..., 1]).astype(np.int8)
    summary = run.contact_summary.reshape(n, len(joints), len(CONTACT_SUMMARY))
    columns = dict(zip(CONTACT_SUMMARY, np.moveaxis(summary, 2, 0), strict=True))
    out: dict[str, np.ndarray] = {"penetration": pen, "contact_mode": mode}
    for name, column in (
        ("peak_contact_force", "pkf"),
        ("max_penetration", "pkd"),
        ("free_flight_time", "tff"),
        ("first_separation_time", "tse"),
    ):
        values = np.full((n, model.njoint), np.nan)
        values[:, joints] = columns[column]
        out[name] = values
    impacts = np.full((n, model.njoint), -1, dtype=np.int32)
    counted = columns["nim"]
    impacts[:, joints] = np.where(np.isnan(counted), -1, counted).astype(np.int32)
    out["impact_count"] = impacts
    return out


METHODS: dict[str, Method] = {
    m.name: m
    for m in (
        Method("rk4", _run_rk4, "classical RK4 on the index-1 form with Baumgarte"),
        Method(
            "rk4-projection",
            _run_rk4_projection,
            "RK4 on the index-1 form (no Baumgarte), then q and v projected onto the "
            "constraints after each step; robust at rank loss (dependent rows dropped, the "
            "basic solution of S λ = r used, instead of a SINGULAR flag)",
        ),
        Method(
            "generalized-alpha",
            _run_generalized_alpha,
            "index-3 generalized-α (Arnold & Brüls), Newton on the KKT system, ρ∞ settable",
        ),
        Method(
            "rk45",
            _run_rk45,
            "Dormand–Prince 5(4) with per-sample step control on the index-1 form (Baumgarte)",
        ),
        Method(
            "radau",
            _run_radau,
            "Radau IIA(5), scipy's algorithm compiled, one sample at a time (reference)",
        ),
    )
}
"""Every integration method by its ``[simulate] method`` name."""


def simulate(
    model: Model,
    sim: Simulate | Mapping[str, Any],
    q_start: np.ndarray | None = None,
    v_start: np.ndarray | None = None,
    history_dtype: Any = np.float32,
    status: np.ndarray | None = None,
    lanes: int | None = None,
    diagnostics: bool = False,
    outputs: Any = None,
    histories: bool = True,
) -> dict[str, np.ndarray]:
    """Integrate every sample of ``model`` as ``sim`` (the ``[simulate]`` section) says.

    Args:
        model: the compiled model (a chunk of samples).
        sim: the ``[simulate]`` section (a validated ``Simulate``, or its table as a dict).
        q_start, v_start: (nsample or 1, 3 nbody) start state overriding ``model.q0/v0``.
        history_dtype: dtype of the histories (float32 or float64).
        status: (nsample,) incoming status bits (e.g. from assembly); failed samples are
            not integrated.
        lanes: instances per lane group of the lane kernels (1 up to the row length of the
            scene's lane kernels, :func:`mcchain.codegen.generate.lane_rows`, which is also
            the default: one to four SIMD registers of doubles).
        diagnostics: also return, per sample, int64 (nsample,): ``steps`` (accepted
            steps), ``rejected_steps`` and ``evaluations`` (right-hand-side evaluations).
            rk4, rk4-projection: ``steps`` = the steps to t_end (``OutputGrid.nstep``:
            whole steps of dt and the last one, shortened to land on t_end) for every
            integrated sample (a failed one is carried to the end with NaN), ``rejected_steps`` 0,
            ``evaluations`` 4 per step + 1 (stage 0 at t_end, for the last outputs; the
            projection's Newton iterations evaluate Φ, not accelerations, and are not
            counted). rk45: accepted and rejected attempts up to the end or the failure;
            ``evaluations`` 1 (the first stage) + 6 per attempt (7 stages, the last one is
            the next step's first: FSAL). radau: the accepted steps and the right-hand-side
            evaluations over all segments (scipy's ``nfev``; the finite-difference
            Jacobian's not included; a sample stopped by a singular evaluation reports
            every call up to it); ``rejected_steps`` -1, not counted. generalized-alpha:
            the steps completed (up to a failure), ``rejected_steps`` 0, ``evaluations`` 1
            (the start's index-1 solve) + one residual per Newton iteration (+ 1: the
            index-1 solve after a last step shortened to land on t_end). Samples failed
            on entry: all 0 (radau's ``rejected_steps`` -1).
        outputs: the ``[[output]]``s to track (:class:`mcchain.solvers.output_plan.OutputPlan`,
            for this model: with a relative one, the model carries its ideal copy); their
            values are returned as ``output_values`` (sample, nout), NaN for a failed sample.
        histories: False: no time history is stored (``[storage] histories = "none"``):
            ``time`` and every history come back with 0 times (shape (nsample, 0, ...)),
            nothing allocated, filled or written for them; every per-sample value (status,
            peaks, contact summaries, outputs, diagnostics) is the same, bit for bit (the
            steps still land on every output time).

    Returns:
        Arrays by ensemble variable name (see the module docstring), plus ``status``,
        ``diverged_time``, ``singular_time``, ``contact_lost_time``.
    """
    settings = load_section(Simulate, "simulate", sim)
    if settings.kernels == "auto":  # a run resolves it for all its samples (mcchain.runner.job)
        choice = choose_kernels(settings, model.ndof, model.nsample)
        settings = settings.model_copy(update={"kernels": choice.kernels})
    grid = output_times(settings)
    time, every = grid.time, grid.every
    q, v, status = start_state(model, settings, q_start, v_start, status)
    if model.has_contact:  # each contact-law joint starts where its journal is
        model = replace(model, joint_start=start_modes(model, q))
    stored = len(time) if histories else 0
    out = _allocate(model, stored, history_dtype)
    n = model.nsample
    ncj = int(np.count_nonzero(model.joint_model))
    run = _Run(
        model=model,
        settings=settings,
        q=q,
        v=v,
        time=time,
        every=every,
        dt=grid.dt,
        nstep=grid.nstep,
        last_step=grid.last_step,
        out=out,
        status=status,
        t_div=np.full(n, np.nan),
        t_sing=np.full(n, np.nan),
        t_cl=np.full(n, np.nan),
        steps=np.zeros(n, np.int64),
        rejected_steps=np.zeros(n, np.int64),
        evaluations=np.zeros(n, np.int64),
        lanes=None if lanes is None else int(lanes),
    )
    if ncj:
        run.contact_history = np.full((n, stored, 2 * ncj), np.nan)
        run.contact_summary = np.full((n, len(CONTACT_SUMMARY) * ncj), np.nan)
    run.peaks = np.full((n, model.njoint + model.ndriver), np.nan)
    from mcchain.solvers.output_plan import empty_plan

    run.plan = empty_plan(n) if outputs is None else outputs
    run.output_values = np.full((n, len(run.plan.names)), np.nan)
    if n:
        METHODS[settings.method].run(run)
    result = {"time": time[:stored], **out, **_peak_outputs(model, run.peaks)}
    if model.has_prismatic:
        result.update(_prismatic_moments(model, result["contact_force"]))
    if model.has_slider_drivers:
        result.update(_slider_forces(model, result["driver_torque"]))
        result["peak_driver_force"] = _slider_forces(model, result["peak_driver_torque"])[
            "driver_force"
        ]
    if ncj:
        result.update(_contact_outputs(run, history_dtype))
    if outputs is not None:
        result["output_values"] = run.output_values
    result["status"] = run.status
    result["diverged_time"] = run.t_div
    result["singular_time"] = run.t_sing
    result["contact_lost_time"] = run.t_cl
    if diagnostics:
        result["steps"] = run.steps
        result["rejected_steps"] = run.rejected_steps
        result["evaluations"] = run.evaluations
    return result
