"""``radau``: Radau IIA(5) one sample at a time, in segments between located events — the
slow, independent reference of every method, with and without contact-law joints (without
them, one segment and no events).

The steps are :mod:`mcchain.kernels.radau` (scipy's Radau, compiled, on the index-1
accelerations of :func:`mcchain.kernels.explicit.index1_acceleration`, through its one
stepping entry :func:`~mcchain.kernels.radau.radau_kernel`); this driver does
what ``scipy.integrate.solve_ivp`` did around them: evaluates the events after each accepted
step, locates a crossing on the step's dense output (``brentq``, as solve_ivp), writes the
outputs at the output times the step passed from its dense output, and starts a new
segment after an event. Within a segment every contact-law joint keeps its mode, so the
right-hand side is smooth. A segment ends at the first of these events:

* onset of a contact (δ crosses 0 upwards): D is fixed from δ̇⁻ there (exact, no "first
  instants" as in a fixed-step kernel);
* separation (δ crosses 0 downwards);
* model auto on the link: λ_r crosses 0 downwards (the switch to the law);
* model auto under the law: the re-seat dwell complete, (t − t_s) ω_c(t) = 2π
  RESEAT_PERIODS, located on the dense output as the other events, t_s being the located
  instant the criterion (:func:`mcchain.kernels.clearance.reseat_margin`, checked at every
  accepted step's end) last began to hold; then the projection onto the link
  (:func:`mcchain.kernels.explicit.reseat`). Neither instant depends on the steps.

Peaks of the forces and of the penetration of the joints in contact are located on each
segment's dense output (:mod:`mcchain.solvers.peaks`), impacts and free-flight time at the
events.
"""

from __future__ import annotations

import bisect
import functools
import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, NamedTuple, Protocol

import numpy as np

from mcchain.contact import AUTO, RESEAT_PERIODS, SEATED, SEATED_AT_SWITCH, seat_tolerance
from mcchain.model import JOINT_CLEARANCE
from mcchain.solvers.history_rows import float64_rows, store_rows
from mcchain.status import CONTACT_LOST, DIVERGED, FAILURE_BITS, SINGULAR

if TYPE_CHECKING:
    from mcchain.model import Model
    from mcchain.scene.models import Simulate

EVENT_XTOL = 4.0 * float(np.finfo(float).eps)
"""brentq's absolute and relative tolerance on an event's time (solve_ivp's)."""


def locate_root(f: Callable[[float], float], t_old: float, t: float) -> float:
    """The root of ``f`` in the bracket [t_old, t] (s; ``f`` changes sign over it), to
    :data:`EVENT_XTOL`, by scipy's ``brentq`` (as solve_ivp locates its events).

    scipy.optimize is imported here, where it is used (as by the peaks,
    :mod:`mcchain.solvers.peaks`): its import costs 0.2-0.9 s of CPU (scipy.fft,
    scipy.special, linprog, ...), more than a warm run's kernels take to load."""
    from scipy.optimize import brentq

    return float(brentq(f, t_old, t, xtol=EVENT_XTOL, rtol=EVENT_XTOL))


def _event_on_step(
    event: Callable[[float, np.ndarray], float],
    step: tuple[float, float, np.ndarray, np.ndarray],
    t: float,
) -> float:
    """``event`` at t (s) on the dense output of one accepted ``step`` (:class:`_Dense`)."""
    return float(event(t, _Dense.piece(t, step)))


class RadauRun(Protocol):
    """What :func:`run_radau` reads and writes of a run (``mcchain.solvers.simulate``'s):
    the model and settings, the start state (nsample, ndof), the output times (ntime,), the
    per-sample status, failure times and diagnostics (nsample,), and the contact arrays
    (None without contact-law joints)."""

    model: Model
    settings: Simulate
    q: np.ndarray
    v: np.ndarray
    time: np.ndarray
    status: np.ndarray
    t_div: np.ndarray
    t_sing: np.ndarray
    t_cl: np.ndarray
    steps: np.ndarray
    rejected_steps: np.ndarray
    evaluations: np.ndarray
    contact_history: np.ndarray | None
    contact_summary: np.ndarray | None
    peaks: np.ndarray | None
    output_values: np.ndarray | None

    def output_args(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]: ...


def run_radau(run: RadauRun, flat: tuple[np.ndarray, ...], singular_pivot: float) -> None:
    """Integrate every sample of ``run`` with Radau into the history arrays ``flat`` (the
    kernels' layout: q, v, joint force, contact force, driver torque, constraint error,
    energy, each (sample, time, ...)); the contact arrays as the lane kernels'."""
    from mcchain.kernels.explicit import nan_history

    run.rejected_steps[:] = -1  # the rejected attempts are not counted
    n, ntime = run.model.nsample, flat[-1].shape[1]
    contact = (
        (run.contact_history, run.contact_summary)
        if run.contact_history is not None and run.contact_summary is not None
        else (np.zeros((n, ntime, 0)), np.zeros((n, 0)))
    )
    shared = (run.model.kernel_model(), *run.model.constraint_pattern())
    for i in range(n):
        rows = float64_rows(flat, i, i + 1)  # the sample's histories as the kernels write them
        if run.status[i] & FAILURE_BITS:
            nan_history(0, 0, *rows)
        else:
            _Sample(run, i, singular_pivot, rows, contact, shared).integrate()
        store_rows(flat, i, rows)


class _Dense:
    """The dense output of a segment's accepted steps, as scipy's ``OdeSolution``: the
    state at t (s) by the step that holds t; ``ts`` the step ends, the segment's start
    first."""

    def __init__(self, t0: float) -> None:
        self.ts = [t0]
        self.pieces: list[tuple[float, float, np.ndarray, np.ndarray]] = []

    def add(self, t_old: float, t: float, y_old: np.ndarray, Q: np.ndarray) -> None:
        self.ts.append(t)
        self.pieces.append((t_old, t - t_old, y_old.copy(), Q.copy()))

    def clip(self, t: float) -> None:
        """The last step ends at t (an event inside it)."""
        self.ts[-1] = t

    @staticmethod
    def piece(t: float, piece: tuple[float, float, np.ndarray, np.ndarray]) -> np.ndarray:
        t_old, h, y_old, Q = piece
        x = (t - t_old) / h
        return y_old + Q @ np.array([x, x * x, x * x * x])

    def __call__(self, t: float) -> np.ndarray:
        k = bisect.bisect_left(self.ts, t)  # on the list itself: O(log n), no copy
        return self.piece(t, self.pieces[min(max(k - 1, 0), len(self.pieces) - 1)])


class _Sample:
    """One sample's integration: its modes (``cst``, :mod:`mcchain.kernels.clearance`),
    scratch arrays, and the callbacks solve_ivp takes."""

    def __init__(
        self,
        run: RadauRun,
        i: int,
        pivot: float,
        flat: tuple[np.ndarray, ...],
        contact: tuple[np.ndarray, np.ndarray],
        shared: tuple[Any, ...],
    ) -> None:
        """``flat``: this sample's histories, one float64 row each
        (:func:`~mcchain.solvers.history_rows.float64_rows`); ``contact``: the contact
        history and summary arrays of every sample (empty without contact-law joints);
        ``shared``: the kernel model and the constraint pattern, built once per run."""
        from mcchain.kernels import clearance as cl
        from mcchain.kernels import radau as kr
        from mcchain.kernels.explicit import index1_acceleration
        from mcchain.kernels.forces import mass_diagonal

        model = run.model
        self.run, self.i, self.pivot, self.flat, self.cl = run, i, pivot, flat, cl
        self.contact = contact
        self.model, self.ndof = model, model.ndof
        self.km, self.cols, self.first = shared
        self.joints = np.flatnonzero(model.joint_model)
        self.rows = model.joint_row[self.joints]
        ncon, ndof = model.ncon, model.ndof
        self.B, self.S = np.zeros((ncon, ndof)), np.zeros((ncon, ncon))
        self.F, self.qdd = np.zeros(ndof), np.zeros(ndof)
        self.g, self.phi, self.lam = np.zeros(ncon), np.zeros(ncon), np.zeros(ncon)
        self.row_law = np.zeros((ncon, 3))
        self.scratch = [np.zeros(ncon) for _ in range(4)]
        self.jf, self.cf = np.zeros((model.njoint, 2)), np.zeros(model.njoint)
        self.minv = np.zeros(ndof)
        mass_diagonal(self.km, i, self.minv)
        self.minv = 1.0 / self.minv
        self.cst = np.zeros((len(self.joints), cl.NCST))
        if len(self.joints):  # without contact-law joints it has nothing to do: not loaded
            cl.contact_start(self.km, i, self.cst)
        self.alpha2, self.beta2 = 2.0 * run.settings.gains[0], run.settings.gains[1] ** 2
        # per joint: the located instant its re-seat criterion began to hold (NaN: not now)
        self.ready_since = [math.nan] * len(self.joints)
        self.last_step: tuple[float, float, np.ndarray, np.ndarray] | None = None
        self.step_penetration: list[np.ndarray] = []  # δ at the segment's step ends (the hook)
        self.free_since = [math.nan] * len(self.joints)
        # the compiled stepper's arrays (mcchain.kernels.radau.radau_kernel)
        n = 2 * ndof
        self.kr = kr
        # bound here: an import in accelerations() cost 0.8 µs of its ~4 calls a step
        self.index1_acceleration = index1_acceleration
        self.acc = (self.minv, self.cols, self.first, self.cst, self.row_law, self.B, self.S,
                    self.F, self.g, self.phi, self.qdd, self.lam)  # fmt: skip
        self.stepper = dict(
            f=np.zeros(n), J=np.zeros((n, n)), LUr=np.zeros((n, n)),
            piv_r=np.zeros(n, np.int64), LUc=np.zeros((n, n), complex),
            piv_c=np.zeros(n, np.int64), Z=np.zeros((3, n)), W=np.zeros((3, n)),
            F=np.zeros((3, n)), y_old=np.zeros(n), Q=np.zeros((n, 3)),
        )  # fmt: skip
        self.state = np.zeros(kr.NSTATE)
        self.work = (np.zeros(n), np.zeros(n), np.zeros(n, complex))
        self.tolerances = (float(run.settings.rtol), float(run.settings.atol))
        order = ("f", "J", "LUr", "piv_r", "LUc", "piv_c", "Z", "W", "F", "y_old", "Q")
        # radau_kernel's arguments after y, in its order
        self.kernel_arrays = (
            *(self.stepper[k] for k in order), *self.tolerances, self.state, *self.work,
            self.alpha2, self.beta2, self.pivot, *self.acc,
        )  # fmt: skip
        self.peaks = np.zeros(model.njoint + model.ndriver)  # mcchain.kernels.peaks' order
        # [[output]]s: their state, and the signals at the segment's step ends (the hook)
        from mcchain.kernels.outputs import output_state

        self.spec, self.data, _values = run.output_args()
        if self.spec.shape[0]:  # without [[output]]s: no output state, no kernel loaded
            self.ot, self.oscratch = output_state(self.km, self.spec.shape[0])
        self.step_signals: list[tuple[float, np.ndarray, np.ndarray]] = []

    # -- the right-hand side and the step hook ---------------------------------------------
    def kernel(self, op: int, t: float, t_bound: float, y: np.ndarray) -> int:
        """:func:`mcchain.kernels.radau.radau_kernel` ``op`` (START, STEP) of this sample at
        (t, y), y the stepper's state (2 ndof,), towards ``t_bound``; its code."""
        return int(self.kr.radau_kernel(op, t, self.km, self.i, t_bound, y, *self.kernel_arrays))

    def accelerations(self, t: float, y: np.ndarray) -> float:
        """q̈ and λ into ``qdd``, ``lam`` at (t, y) with the present modes; max |Φ| (< 0:
        rank loss, see index1_acceleration). The driver's most frequent call (about 4 times
        a step): index1_acceleration itself, whose 20 arguments numba takes from Python
        1.6 µs faster than the stepping entry's 38."""
        q, v = np.ascontiguousarray(y[: self.ndof]), np.ascontiguousarray(y[self.ndof :])
        return float(
            self.index1_acceleration(
                self.km, self.i, q, v, t, self.alpha2, self.beta2, self.pivot, *self.acc
            )
        )

    def in_contact(self) -> np.ndarray:
        """Which contact-law joints are in contact under the law in the present modes (INS:
        δ > 0, or seated): the joints whose penetration peak is tracked."""
        cl, cst = self.cl, self.cst
        return (cst[:, cl.FM] == 1.0) & (cst[:, cl.INS] == 1.0)

    def penetrations(self, t: float, y: np.ndarray) -> np.ndarray:
        """δ (m) of each contact-law joint at (t, y), NaN off :meth:`in_contact`."""
        return np.array([
            self.penetration(j, y) if tracked else math.nan
            for j, tracked in enumerate(self.in_contact())
        ])  # fmt: skip

    def segment_peaks(self, dense: _Dense, clipped: bool) -> None:
        """The continuous peaks over the segment's steps (``clipped``: the last one ends at
        its event), in its modes: of |joint force| per joint and |λ| per driver (``peaks``),
        and of δ of the joints in contact (their PKD column, the kernels' max_penetration),
        from δ at the step ends the hook recorded (``step_penetration``)."""
        from mcchain.solvers.peaks import dense_peaks

        ts = np.array(dense.ts)
        dense_peaks(dense, ts, self.quantities, self.peaks)
        if len(self.joints):
            values = np.array(self.step_penetration)
            if clipped:
                values[-1] = self.penetrations(ts[-1], dense(ts[-1]))
            dense_peaks(dense, ts, self.penetrations, self.cst[:, self.cl.PKD], values)

    def quantities(self, t: float, y: np.ndarray) -> np.ndarray:
        """|joint force| per joint and |λ| per driver at (t, y) with the present modes."""
        from mcchain.kernels.peaks import peak_values

        self.accelerations(t, y)
        values = np.zeros(len(self.peaks))
        peak_values(self.km, self.lam, self.cst, values)
        return values

    def on_step(self, t: float, y: np.ndarray) -> float:
        """The hook at every accepted step's end (and a segment's start), the first of the
        events, evaluated before the others (it never fires): the step count, δ of the joints
        in contact (for :meth:`segment_peaks`), and where a re-seat dwell of model auto began
        (located on the step ``last_step`` where the criterion turned true; reset where it
        is false at the step's end), from the accelerations the stepper evaluated last, at
        (t, y)."""
        cl, cst, step = self.cl, self.cst, self.last_step
        self.run.steps[self.i] += 1  # q̈, λ, cst: at (t, y), where the stepper left them
        if self.spec.shape[0]:
            self.step_signals.append((t, *self.signals(t, y, evaluate=False)))
        self.step_penetration.append(np.where(self.in_contact(), cst[:, cl.PEN], math.nan))
        ready = [self.reseat_margin(j, t, y, evaluate=False) > 0.0 for j in range(len(self.joints))]
        for j in range(len(self.joints)):
            if cst[j, cl.FM] != 1.0:
                continue
            if not ready[j]:
                self.ready_since[j] = math.nan
            elif math.isnan(self.ready_since[j]) and step is not None:
                t_old = step[0]
                margin = functools.partial(self.step_margin, j, step)
                self.ready_since[j] = (
                    t_old if margin(t_old) > 0.0 else locate_root(margin, t_old, t)
                )
        return 1.0

    def signals(
        self, t: float, y: np.ndarray, evaluate: bool = True
    ) -> tuple[np.ndarray, np.ndarray]:
        """The ``[[output]]``s' signals and rates at (t, y) (``evaluate`` False: from the last
        evaluation, there), in the present modes."""
        from mcchain.kernels.outputs import output_values_at

        if evaluate:
            self.accelerations(t, y)
        q, v = np.ascontiguousarray(y[: self.ndof]), np.ascontiguousarray(y[self.ndof :])
        f, r = output_values_at(
            self.km, self.i, self.spec, self.data, q, v, self.qdd, self.lam, self.cst,
            self.oscratch,
        )  # fmt: skip
        return f.copy(), r.copy()

    def segment_outputs(self, dense: _Dense, clipped: bool) -> None:
        """Feed the ``[[output]]``s the segment's step ends (``clipped``: the last one at its
        event, evaluated on the dense output), in its modes."""
        from mcchain.kernels.outputs import outputs_feed

        points = self.step_signals
        self.step_signals = []
        if not points:
            return
        if clipped:
            stop = float(dense.ts[-1])
            points[-1] = (stop, *self.signals(stop, dense(stop)))
        for t, f, r in points:
            outputs_feed(self.i, self.ot, self.spec, self.data, t, f, r)

    def reseat_margin(self, j: int, t: float, y: np.ndarray, evaluate: bool = True) -> float:
        """:func:`mcchain.kernels.clearance.reseat_margin` of contact-law joint ``j`` at
        (t, y) (``evaluate`` False: from the last evaluation, there)."""
        if evaluate:
            self.accelerations(t, y)
        cl, cst, r = self.cl, self.cst, self.rows[j]
        if cst[j, cl.FM] != 1.0:
            return -1.0
        from mcchain.kernels.forces import kinetic_energy

        kinetic = kinetic_energy(self.km, self.i, np.ascontiguousarray(y[self.ndof :]))
        return float(cl.reseat_margin(
            self.km, self.i, int(self.joints[j]), self.lam[r], cst[j, cl.PEN],
            cst[j, cl.PDOT], self.pulsation(j), kinetic,
        ))  # fmt: skip

    def step_margin(
        self, j: int, step: tuple[float, float, np.ndarray, np.ndarray], t: float
    ) -> float:
        """:meth:`reseat_margin` at t on the accepted step ``step``'s dense output."""
        return self.reseat_margin(j, t, _Dense.piece(t, step))

    def pulsation(self, j: int) -> float:
        """ω_c of contact-law joint ``j`` (1/s) at the last evaluation."""
        wj = self.cst[j, self.cl.KC] * self.row_law[self.rows[j], 2]
        return math.sqrt(wj) if wj > 0.0 else 0.0

    # -- events ----------------------------------------------------------------------------
    def penetration(self, j: int, y: np.ndarray) -> float:
        """δ = |d| − c of contact-law joint ``j`` at (q of) ``y``, m."""
        from mcchain.kernels.joints import joint_vectors

        k = int(self.joints[j])
        q = np.ascontiguousarray(y[: self.ndof])
        *_, dx, dy = joint_vectors(self.km, self.i, q, k)
        return math.hypot(dx, dy) - self.clearance(j)

    def clearance(self, j: int) -> float:
        """The clearance c of contact-law joint ``j`` in this sample, m."""
        k = int(self.joints[j])
        return float(self.model.joint_clearance[self.i % self.model.joint_clearance.shape[0], k])

    def events(self) -> tuple[list[Callable[..., float]], list[tuple[str, int]]]:
        """The events of the next segment (after the step hook) and what each watches."""
        cl = self.cl
        found: list[Callable[..., float]] = [self.on_step]
        kinds: list[tuple[str, int]] = []
        for j, k in enumerate(self.joints):
            if self.cst[j, cl.FM] == 1.0:
                gap = functools.partial(self.gap, j)
                found.append(_event(gap, -1.0 if self.cst[j, cl.INS] == 1.0 else 1.0))
                kinds.append(("gap", j))
                if self.cst[j, cl.VI] == SEATED_AT_SWITCH:  # free flight until it presses
                    found.append(_event(functools.partial(self.pressed, j), 1.0))
                    kinds.append(("press", j))
            elif self.model.joint_model[k] == AUTO:
                found.append(_event(functools.partial(self.link_force, int(self.rows[j])), -1.0))
                kinds.append(("switch", j))
        found.append(_event(self.reseat_clock, 1.0))
        kinds.append(("reseat", -1))
        return found, kinds

    def gap(self, j: int, t: float, y: np.ndarray) -> float:
        """Event: δ of contact-law joint ``j`` (seated, VI < 0: δ + the seat tolerance, so
        that its contact ends where the journal is that far off the wall)."""
        if self.cst[j, self.cl.VI] < 0.0:
            return self.penetration(j, y) + seat_tolerance(self.clearance(j))
        return self.penetration(j, y)

    def pressed(self, j: int, t: float, y: np.ndarray) -> float:
        """Event: δ − the seat tolerance of contact-law joint ``j`` (seated by the switch of
        auto: the journal presses back where it rises through 0)."""
        return self.penetration(j, y) - seat_tolerance(self.clearance(j))

    def link_force(self, r: int, t: float, y: np.ndarray) -> float:
        """Event: λ of row ``r`` (a joint of model auto on the link)."""
        self.accelerations(t, y)
        return float(self.lam[r])

    def reseat_clock(self, t: float, y: np.ndarray) -> float:
        """Event, rising through 0 where a re-seat dwell is complete: the largest
        (t − t_s) ω_c(t) − 2π RESEAT_PERIODS over the joints whose criterion holds since t_s
        (< 0 before t_s); −1 if none."""
        if all(math.isnan(since) for since in self.ready_since):
            return -1.0
        self.accelerations(t, y)
        return max(self.dwells(t)) - 2.0 * math.pi * RESEAT_PERIODS

    def dwells(self, t: float) -> list[float]:
        """(t − t_s) ω_c of each contact-law joint whose re-seat criterion holds since t_s
        (−inf for the others), ω_c from the last evaluation."""
        return [(t - since) * self.pulsation(j) if not math.isnan(since) else -math.inf
                for j, since in enumerate(self.ready_since)]  # fmt: skip

    def handle(self, kind: str, j: int, t: float, y: np.ndarray) -> np.ndarray:
        """Apply the event ``kind`` of contact-law joint ``j`` at (t, y); the state to go on
        from."""
        from mcchain.kernels.explicit import reseat

        cl, cst = self.cl, self.cst
        if kind == "gap":
            self.accelerations(t, y)
            if cst[j, cl.INS] == 0.0:  # onset: δ̇⁻ located
                cst[j, cl.VI] = cst[j, cl.PDOT]
                cst[j, cl.INS] = 1.0
                cst[j, cl.NIM] += 1.0
                if not math.isnan(self.free_since[j]):
                    cst[j, cl.TFF] += t - self.free_since[j]
                self.free_since[j] = math.nan
            else:  # separation (also the end of a seated contact)
                self.ready_since[j] = math.nan
                cst[j, cl.INS] = 0.0
                if cst[j, cl.VI] != SEATED_AT_SWITCH:  # that one flies free since the switch
                    self.free_since[j] = t
                cst[j, cl.VI] = 0.0
                if math.isnan(cst[j, cl.TSE]):
                    cst[j, cl.TSE] = t
        elif kind == "press":  # seated by the switch, the journal presses back: contact
            cst[j, cl.TFF] += t - self.free_since[j]
            self.free_since[j] = math.nan
            cst[j, cl.VI] = SEATED
        elif kind == "switch":
            self.ready_since[j] = math.nan
            cst[j, cl.FM] = 1.0  # seated: the link's δ is 0 up to rounding
            cst[j, cl.VI] = SEATED_AT_SWITCH
            cst[j, cl.INS] = 1.0
            self.free_since[j] = t  # the link's λ is 0: the journal leaves the wall here
            if math.isnan(cst[j, cl.TSE]):
                cst[j, cl.TSE] = t
        else:  # re-seat of the joint whose dwell completed (the clock's largest)
            self.accelerations(t, y)
            done = int(np.argmax(self.dwells(t)))
            cst[done, cl.DWL], self.ready_since[done] = -1.0, math.nan
            if not math.isnan(self.free_since[done]):  # still seated by its switch
                cst[done, cl.TFF] += t - self.free_since[done]
                self.free_since[done] = math.nan
            q, v = y[: self.ndof].copy(), y[self.ndof :].copy()
            reseat(
                self.km, self.i, q, v, t, self.minv, self.cols, self.first, cst, self.row_law,
                self.pivot, self.B, self.S, *self.scratch,
            )  # fmt: skip
            y = np.concatenate([q, v])
        return y

    # -- the whole run ---------------------------------------------------------------------
    def integrate(self) -> None:
        from mcchain.kernels import radau as kr
        from mcchain.kernels.explicit import finish_contact, nan_history

        run, i, cl, cst = self.run, self.i, self.cl, self.cst
        t_end = float(run.time[-1])
        t, y = 0.0, np.concatenate([run.q[i], run.v[i]])
        for j in range(len(self.joints)):  # a free start watches its onset
            if cst[j, cl.FM] == 1.0 and cst[j, cl.VI] >= 0.0 and self.penetration(j, y) <= 0.0:
                self.free_since[j] = 0.0
                cst[j, cl.INS] = 0.0
        self.accelerations(t, y)  # model auto starts on the link only where it pushes
        for j, k in enumerate(self.joints):
            if cst[j, cl.FM] == 0.0 and self.model.joint_model[k] == AUTO:
                if self.lam[self.rows[j]] <= 0.0:
                    y = self.handle("switch", j, t, y)
        written, fail_bit, fail_time = 0, 0, math.nan
        while True:
            outcome = self.segment(t, y, written)
            written = outcome.written
            if outcome.fail_bit:
                fail_bit, fail_time = outcome.fail_bit, outcome.fail_time
                break
            if outcome.event is None:  # t_end reached
                break
            kind, j = outcome.event
            t = outcome.t
            assert outcome.y is not None
            y = self.handle(kind, j, t, outcome.y)
        run.evaluations[i] = int(self.state[kr.NFEV])
        for j in range(len(self.joints)):
            if not math.isnan(self.free_since[j]) and not fail_bit:
                cst[j, cl.TFF] += t_end - self.free_since[j]
        if fail_bit:
            run.status[i] |= fail_bit
            (run.t_div if fail_bit == DIVERGED else run.t_sing)[i] = fail_time
        if written < self.flat[-1].shape[1]:  # times left unwritten: loaded only then
            nan_history(0, written, *self.flat)
        assert run.peaks is not None
        run.peaks[i] = np.nan if fail_bit else self.peaks
        if self.spec.shape[0]:
            from mcchain.kernels.outputs import outputs_finish

            values = run.output_args()[2]
            outputs_finish(i, bool(fail_bit), self.ot, self.spec, self.data, values)
        if len(self.joints):
            finish_contact(self.km, i, int(run.status[i]), written, cst, *self.contact, run.peaks)

    def segment(self, t: float, y: np.ndarray, written: int) -> _Segment:
        """Integrate from (t, y) to the first event or t_end, writing the output times from
        index ``written`` on that the steps pass (solve_ivp's loop around its solver)."""
        from mcchain.kernels import radau as kr

        run, i, st = self.run, self.i, self.stepper
        t_end, times = float(run.time[-1]), run.time
        events, kinds = self.events()
        y = np.array(y, dtype=float)
        code = self.kernel(kr.START, t, t_end, y)
        if code != kr.ACCEPTED:
            return _Segment(written, SINGULAR, float(self.state[kr.T_FAIL]))
        self.last_step = None
        self.step_penetration = []
        self.step_signals = []
        g = [event(t, y) for event in events]
        run.steps[i] -= 1  # the hook's call at the segment's start
        dense = _Dense(t)
        while t < t_end:
            code = self.kernel(kr.STEP, t, t_end, y)
            if code == kr.SINGULAR_EVALUATION:
                return _Segment(written, SINGULAR, float(self.state[kr.T_FAIL]))
            if code != kr.ACCEPTED:
                return _Segment(written, DIVERGED, t)
            t_old, t = float(self.state[kr.T_OLD]), float(self.state[kr.T_NOW])
            dense.add(t_old, t, st["y_old"], st["Q"])
            step = self.last_step = dense.pieces[-1]
            g_new = [event(t, y) for event in events]
            found: tuple[float, int] | None = None
            for e, event in enumerate(events):
                if not _crosses(g[e], g_new[e], getattr(event, "direction", 0.0)):
                    continue
                root = locate_root(functools.partial(_event_on_step, event, step), t_old, t)
                if found is None or root < found[0]:
                    found = (root, e)
            stop = t if found is None else found[0]
            while written < len(times) and times[written] <= stop:
                tw = float(times[written])
                err = self.write(written, tw, _Dense.piece(tw, step))
                if not err <= run.settings.constraint_tolerance:
                    return _Segment(written, DIVERGED, tw)
                written += 1
            g = g_new
            if found is not None:
                dense.clip(stop)
                self.segment_peaks(dense, clipped=True)
                self.segment_outputs(dense, clipped=True)
                y_stop = _Dense.piece(stop, step)
                return _Segment(written, 0, math.nan, kinds[found[1] - 1], stop, y_stop)
        if dense.pieces:  # the segment's peaks, in its modes
            self.segment_peaks(dense, clipped=False)
            self.segment_outputs(dense, clipped=False)
        return _Segment(written, 0, math.nan)

    def write(self, it: int, t: float, y: np.ndarray) -> float:
        """The outputs at history index ``it`` (as the kernels write them) and the contact
        loss of link clearance joints; max |Φ|."""
        from mcchain.kernels.explicit import write_outputs

        run, model, cl = self.run, self.model, self.cl
        err = abs(self.accelerations(t, y))
        cl.record_stage0(self.km, self.cst, self.row_law)
        q, v = np.ascontiguousarray(y[: self.ndof]), np.ascontiguousarray(y[self.ndof :])
        write_outputs(
            self.km, self.i, 0, it, q, v, self.lam, self.cst, self.jf, self.cf, err, *self.flat,
            self.contact[0],
        )  # fmt: skip
        for k in range(model.njoint):
            clearance_link = model.joint_kind[k] == JOINT_CLEARANCE and model.joint_model[k] == 0
            lost = clearance_link and self.lam[model.joint_row[k]] <= 0.0
            if lost and not run.status[self.i] & CONTACT_LOST:
                run.status[self.i] |= CONTACT_LOST
                run.t_cl[self.i] = t
        return err


def _event(function: Callable[[float, np.ndarray], float], direction: float) -> Any:
    """``function`` as a terminal solve_ivp event in ``direction``."""

    def event(t: float, y: np.ndarray) -> float:
        return function(t, y)

    event.terminal = True  # type: ignore[attr-defined]
    event.direction = direction  # type: ignore[attr-defined]
    return event


class _Segment(NamedTuple):
    """How a segment ended: the output times written so far, a failure (status bit, time)
    or the event that ended it (kind and joint, time, state); no event at t_end."""

    written: int
    fail_bit: int
    fail_time: float
    event: tuple[str, int] | None = None
    t: float = math.nan
    y: np.ndarray | None = None


def _crosses(g: float, g_new: float, direction: float) -> bool:
    """Whether an event's value went through 0 in its direction over a step (solve_ivp's
    ``find_active_events``)."""
    up = g <= 0.0 <= g_new
    down = g >= 0.0 >= g_new
    return (up and direction > 0) or (down and direction < 0) or ((up or down) and direction == 0)
