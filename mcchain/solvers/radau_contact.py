"""scipy's Radau with clearance joints under the contact law: one sample at a time, in
segments between located events (the slow reference of the contact law).

Within a segment every contact-law joint keeps its mode, so the right-hand side is smooth
(the index-1 accelerations of :func:`mcchain.kernels.explicit.index1_acceleration`, with the
law's row λ_r = F_n). A segment ends at the first of these events, located by solve_ivp on
its dense output:

* onset of a contact (δ crosses 0 upwards): D is fixed from δ̇⁻ there (exact, no "first
  instants" as in a fixed-step kernel);
* separation (δ crosses 0 downwards);
* model auto on the link: λ_r crosses 0 downwards (the switch to the law);
* model auto under the law: the re-seat criterion met for its dwell
  (:func:`mcchain.kernels.clearance.reseat_ready`, checked at every accepted step), then the
  projection onto the link (:func:`mcchain.kernels.explicit.reseat`).

Peaks of the forces are located on each segment's dense output (:mod:`mcchain.solvers.peaks`),
the peak penetration kept at every accepted step, impacts and free-flight time at the events.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from typing import Any

import numpy as np

from mcchain.contact import AUTO, RESEAT_PERIODS, seat_tolerance
from mcchain.model import JOINT_CLEARANCE
from mcchain.status import CONTACT_LOST, DIVERGED, FAILURE_BITS, SINGULAR


class _Singular(Exception):
    pass


def run_radau_contact(run: Any, singular_pivot: float) -> None:
    """Integrate every sample of ``run`` (a :class:`mcchain.solvers.simulate._Run` whose
    model has contact-law joints) with Radau; outputs as the lane kernels'."""
    from mcchain.kernels.explicit import nan_history
    from mcchain.solvers.simulate import _flat_outputs

    flat = _flat_outputs(run.out, run.model.nsample, len(run.time))
    run.rejected_steps[:] = -1  # scipy's Radau does not count them
    shared = (run.model.kernel_model(), *run.model.constraint_pattern())
    for i in range(run.model.nsample):
        if run.status[i] & FAILURE_BITS:
            nan_history(i, 0, *flat)
            continue
        _Sample(run, i, singular_pivot, flat, shared).integrate()


class _Sample:
    """One sample's integration: its modes (``cst``, :mod:`mcchain.kernels.clearance`),
    scratch arrays, and the callbacks solve_ivp takes."""

    def __init__(
        self, run: Any, i: int, pivot: float, flat: tuple[np.ndarray, ...], shared: tuple[Any, ...]
    ) -> None:
        """``shared``: the kernel model and the constraint pattern, built once per run."""
        from mcchain.kernels import clearance as cl
        from mcchain.kernels.forces import mass_diagonal

        model = run.model
        self.run, self.i, self.pivot, self.flat, self.cl = run, i, pivot, flat, cl
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
        cl.contact_start(self.km, i, self.cst)
        self.alpha2, self.beta2 = 2.0 * run.settings.gains[0], run.settings.gains[1] ** 2
        self.due = math.inf  # when a re-seat's dwell was completed (an accepted step's end)
        self.t_prev = 0.0  # the last accepted step's end
        self.free_since = [math.nan] * len(self.joints)
        self.peaks = np.zeros(model.njoint + model.ndriver)  # mcchain.kernels.peaks' order

    # -- the right-hand side and the step hook ---------------------------------------------
    def accelerations(self, t: float, y: np.ndarray) -> float:
        """q̈ and λ into ``qdd``, ``lam`` at (t, y) with the present modes; max |Φ| (< 0:
        rank loss, see index1_acceleration)."""
        from mcchain.kernels.explicit import index1_acceleration

        q, v = np.ascontiguousarray(y[: self.ndof]), np.ascontiguousarray(y[self.ndof :])
        return float(
            index1_acceleration(
                self.km, self.i, q, v, t, self.alpha2, self.beta2, self.pivot, self.minv,
                self.cols, self.first, self.cst, self.row_law, self.B, self.S, self.F, self.g,
                self.phi, self.qdd, self.lam,
            )
        )  # fmt: skip

    def quantities(self, t: float, y: np.ndarray) -> np.ndarray:
        """|joint force| per joint and |λ| per driver at (t, y) with the present modes."""
        from mcchain.kernels.peaks import peak_values

        self.accelerations(t, y)
        values = np.zeros(len(self.peaks))
        peak_values(self.km, self.lam, self.cst, values)
        return values

    def rhs(self, t: float, y: np.ndarray) -> np.ndarray:
        self.run.evaluations[self.i] += 1
        if self.accelerations(t, y) < 0.0:
            raise _Singular(t)
        return np.concatenate([y[self.ndof :], self.qdd])

    def on_step(self, t: float, y: np.ndarray) -> float:
        """solve_ivp's call once per accepted step (an event that never fires): the step
        count, the peak penetration, and the re-seat dwell of model auto."""
        from mcchain.kernels.forces import kinetic_energy

        cl, cst = self.cl, self.cst
        self.run.steps[self.i] += 1
        self.accelerations(t, y)
        h, self.t_prev = t - self.t_prev, t
        kinetic = kinetic_energy(self.km, self.i, np.ascontiguousarray(y[self.ndof :]))
        for j, k in enumerate(self.joints):
            r = self.rows[j]
            lam_r = self.lam[r]
            if cst[j, cl.FM] != 1.0:
                continue
            d1, r1 = cst[j, cl.PEN], cst[j, cl.PDOT]
            cst[j, cl.PKD] = max(cst[j, cl.PKD], d1)
            wj = cst[j, cl.KC] * self.row_law[r, 2]
            wn = math.sqrt(wj) if wj > 0.0 else 0.0
            if h > 0.0 and cl.reseat_ready(self.km, self.i, k, lam_r, d1, r1, wn, kinetic):
                cst[j, cl.DWL] += h
                if cst[j, cl.DWL] * wn >= 2.0 * math.pi * RESEAT_PERIODS:
                    cst[j, cl.DWL] = -1.0
                    self.due = min(self.due, t)
            elif cst[j, cl.DWL] >= 0.0:
                cst[j, cl.DWL] = 0.0
        return 1.0

    # -- events ----------------------------------------------------------------------------
    def penetration(self, j: int, y: np.ndarray) -> float:
        """δ = |d| − c of contact-law joint ``j`` at (q of) ``y``, m."""
        from mcchain.kernels.joints import joint_vectors

        k = int(self.joints[j])
        q = np.ascontiguousarray(y[: self.ndof])
        *_, dx, dy = joint_vectors(self.km, self.i, q, k)
        clearance = self.model.joint_clearance[self.i % self.model.joint_clearance.shape[0], k]
        return math.hypot(dx, dy) - float(clearance)

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
            elif self.model.joint_model[k] == AUTO:
                found.append(_event(functools.partial(self.link_force, int(self.rows[j])), -1.0))
                kinds.append(("switch", j))
        found.append(_event(self.reseat_clock, 0.0))
        kinds.append(("reseat", -1))
        return found, kinds

    def gap(self, j: int, t: float, y: np.ndarray) -> float:
        """Event: δ of contact-law joint ``j`` (seated, VI < 0: δ + the seat tolerance, so
        that its contact ends where the journal is that far off the wall)."""
        if self.cst[j, self.cl.VI] < 0.0:
            k = int(self.joints[j])
            clearance = self.model.joint_clearance[self.i % self.model.joint_clearance.shape[0], k]
            return self.penetration(j, y) + seat_tolerance(float(clearance))
        return self.penetration(j, y)

    def link_force(self, r: int, t: float, y: np.ndarray) -> float:
        """Event: λ of row ``r`` (a joint of model auto on the link)."""
        self.accelerations(t, y)
        return float(self.lam[r])

    def reseat_clock(self, t: float, y: np.ndarray) -> float:
        """Event: 0 at the end of the accepted step that completed a re-seat dwell."""
        return self.due - t if math.isfinite(self.due) else 1.0

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
                cst[j, cl.INS] = 0.0
                cst[j, cl.VI] = 0.0
                self.free_since[j] = t
                if math.isnan(cst[j, cl.TSE]):
                    cst[j, cl.TSE] = t
        elif kind == "switch":
            cst[j, cl.FM] = 1.0  # seated: the link's δ is 0 up to rounding
            cst[j, cl.VI] = -1.0
            cst[j, cl.INS] = 1.0
            if math.isnan(cst[j, cl.TSE]):
                cst[j, cl.TSE] = t
        else:  # re-seat of the joints marked
            q, v = y[: self.ndof].copy(), y[self.ndof :].copy()
            reseat(
                self.km, self.i, q, v, t, self.minv, self.cols, self.first, cst, self.row_law,
                self.pivot, self.B, self.S, *self.scratch,
            )  # fmt: skip
            y = np.concatenate([q, v])
            self.due = math.inf
        self.t_prev = t
        return y

    # -- the whole run ---------------------------------------------------------------------
    def integrate(self) -> None:
        from scipy.integrate import solve_ivp

        from mcchain.kernels.explicit import finish_contact, nan_history
        from mcchain.solvers.peaks import dense_peaks

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
            events, kinds = self.events()
            try:
                sol = solve_ivp(
                    self.rhs, (t, t_end), y, method="Radau", t_eval=run.time[written:],
                    rtol=run.settings.rtol, atol=run.settings.atol, events=events,
                    dense_output=True,
                )  # fmt: skip
                if sol.sol is not None:  # the segment's peaks, in its modes
                    dense_peaks(sol.sol, sol.sol.ts, self.quantities, self.peaks)
            except _Singular as exc:
                fail_bit, fail_time = SINGULAR, float(exc.args[0])
                break
            run.steps[i] -= 1  # the hook's call at the segment's start
            base = written
            for m, tm in enumerate(sol.t):
                err = self.write(base + m, float(tm), sol.y[:, m])
                if not err <= run.settings.constraint_tolerance:
                    fail_bit, fail_time = DIVERGED, float(tm)
                    break
                written = base + m + 1
            if fail_bit:
                break
            if sol.status == -1:
                fail_bit, fail_time = DIVERGED, float(sol.t[-1]) if len(sol.t) else t
                break
            if sol.status == 0:  # t_end reached
                break
            e = next(e for e in range(1, len(sol.t_events)) if len(sol.t_events[e]))
            t = float(sol.t_events[e][0])
            kind, j = kinds[e - 1]
            y = self.handle(kind, j, t, np.array(sol.y_events[e][0]))
        for j in range(len(self.joints)):
            if not math.isnan(self.free_since[j]) and not fail_bit:
                cst[j, cl.TFF] += t_end - self.free_since[j]
        if fail_bit:
            run.status[i] |= fail_bit
            (run.t_div if fail_bit == DIVERGED else run.t_sing)[i] = fail_time
        nan_history(i, written, *self.flat)
        run.peaks[i] = np.nan if fail_bit else self.peaks
        finish_contact(self.km, i, int(run.status[i]), written, cst, run.contact_history,
                       run.contact_summary, run.peaks)  # fmt: skip

    def write(self, it: int, t: float, y: np.ndarray) -> float:
        """The outputs at history index ``it`` (as the kernels write them) and the contact
        loss of link clearance joints; max |Φ|."""
        from mcchain.kernels.explicit import write_outputs

        run, model, cl = self.run, self.model, self.cl
        err = abs(self.accelerations(t, y))
        cl.record_stage0(self.km, self.cst, self.row_law)
        q, v = np.ascontiguousarray(y[: self.ndof]), np.ascontiguousarray(y[self.ndof :])
        write_outputs(
            self.km, self.i, it, q, v, self.lam, self.cst, self.jf, self.cf, err, *self.flat,
            run.contact_history,
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
