"""The output times of a run and the fixed-step schedule that reaches them.

A plain module (no kernels, no code generator): the integrators (:mod:`.simulate`) step on
this grid, and the disk estimate (:mod:`mcchain.runner.resources`) counts its points.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mcchain.errors import SceneError
from mcchain.scene.models import FIXED_STEP_METHODS, Simulate


@dataclass(frozen=True)
class OutputGrid:
    """The output times of a run and the fixed-step schedule that reaches them.

    Attributes:
        time: (ntime,) k · ``output_dt`` for k = 0, 1, … below t_end, then t_end itself, bit
            for bit, as the last point (a k · ``output_dt`` within :data:`GRID_RTOL` of
            t_end is t_end).
        every: steps of ``dt`` per output interval (fixed-step methods; adaptive ones land
            on every output time and use ``dt`` as their first step only).
        dt: the step as written, s.
        nstep: steps from 0 to t_end (fixed-step methods; 0 for adaptive ones): ``every``
            per output interval, then those of the last interval, up to ``every``.
        last_step: the length of the last step, s: ``dt``, or shorter so that the last
            step lands on t_end when t_end is no whole number of steps after the last
            k · ``output_dt`` (fixed-step methods).

    Step n of a fixed-step method starts at :meth:`step_time` (n), computed from n, never
    accumulated, so two runs that differ only in t_end take the same steps, bit for bit,
    up to the shorter one's last whole step; the kernels compute it the same way.
    """

    time: np.ndarray
    every: int
    dt: float
    nstep: int
    last_step: float

    def step_time(self, n: int) -> float:
        """Time of step n, s: ``time[n // every] + (n % every) · dt``, and t_end for
        n = ``nstep``; an output time is thus the very float the kernels step from."""
        if n == self.nstep:
            return float(self.time[-1])
        return float(self.time[n // self.every] + (n % self.every) * self.dt)


GRID_RTOL = 1e-12
"""A grid point (k · output_dt, or a whole step after the last one) within this, relative to
t_end, below t_end is t_end: the gap is rounding (0.3 / 1e-4 = 2999.9999999999995), not an
interval, and no step that short is taken."""


STEP_ULPS = 8
"""A fixed step is longer than this many ulps of t_end: the rounding of ``time[k] + j · dt``
(:meth:`OutputGrid.step_time`) is at most 2 ulps of t_end, so step starts strictly increase."""


def output_times(settings: Simulate) -> OutputGrid:
    """The output grid of ``settings`` and its fixed-step schedule (see :class:`OutputGrid`)."""
    ratio = settings.output_step / settings.dt
    every = round(ratio)
    fixed = settings.method in FIXED_STEP_METHODS
    if fixed and (every < 1 or abs(ratio - every) > 1e-9 * ratio):
        raise SceneError(
            f"simulate.output_dt: must be a whole multiple of dt = {settings.dt:g} for method "
            f"{settings.method!r}, got {settings.output_step:g}"
        )
    every = max(every, 1)
    t_end, dt, interval = float(settings.t_end), float(settings.dt), float(settings.output_step)
    # Every step of a fixed-step method starts after the one before (the kernels feed each
    # start to the peak tracking, which needs increasing times): dt longer than the rounding
    # of t near t_end (the step before an output time is at least dt / 2 long: ``every`` is
    # the nearest whole number of steps).
    if fixed and dt <= STEP_ULPS * math.ulp(t_end):
        raise SceneError(
            f"simulate.dt: {dt:g} s is within the rounding of the time at t_end = {t_end:g} s "
            f"(at most {STEP_ULPS} ulps); take a larger dt"
        )
    below = t_end - GRID_RTOL * t_end  # a point at or past this is t_end
    # count: the grid points k · output_dt (k < count) strictly below t_end
    count = max(1, math.floor(t_end / interval) + 1)
    while count > 1 and (count - 1) * interval >= below:
        count -= 1
    while count * interval < below:
        count += 1
    time = np.append(np.arange(count) * interval, t_end)
    if not fixed:
        return OutputGrid(time, every, dt, 0, dt)
    # The last interval: whole steps from its start while below t_end, then the step that
    # lands on t_end (dt when t_end is a whole step further, within rounding; else shorter).
    start = float(time[-2])
    whole = max(0, math.floor((t_end - start) / dt))
    while whole > 0 and start + whole * dt >= below:
        whole -= 1
    while start + (whole + 1) * dt < below:
        whole += 1
    # At most ``every`` steps per interval (an output_dt that is a multiple of dt only to
    # within 1e-9 could leave room for one more): the last one then ends at t_end.
    last = min(whole + 1, every)
    lands = last == whole + 1 and abs(start + last * dt - t_end) <= GRID_RTOL * t_end
    grid = OutputGrid(time, every, dt, (count - 1) * every + last, dt)
    if lands:
        return grid
    return OutputGrid(time, every, dt, grid.nstep, t_end - grid.step_time(grid.nstep - 1))
