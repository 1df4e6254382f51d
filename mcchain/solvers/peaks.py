"""Continuous peaks on scipy's dense output (the radau paths; the kernels track theirs at every
step with :mod:`mcchain.kernels.peaks`).

The quantities (|joint force| per joint, |λ| per driver: :func:`mcchain.kernels.peaks.
peak_values`) are evaluated at every accepted step's end; where the step ends show a local
maximum, the maximum is located on the solver's dense output over the two steps beside it by
bounded minimisation (``scipy.optimize.minimize_scalar``, method ``bounded``), so the peak is
the continuous one to the integrator's accuracy. The same procedure, at a tight tolerance,
is the dense reference the tests compare the kernels' peaks against.

scipy.optimize is imported at the first peak located, where it is used (its import costs
0.2-0.9 s of CPU, more than a warm run's kernels take to load): with
:func:`mcchain.solvers.radau.locate_root`, the only places of a run that import it.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

LOCATE_XATOL = 1e-10
"""Bounded minimisation stops when the peak's time is known to this fraction of its
bracket (two steps): the value is then exact to rounding, f'' (1e-10 h)² ≪ the step's error."""


def dense_peaks(
    dense: Callable[[float], np.ndarray],
    ts: np.ndarray,
    quantities: Callable[[float, np.ndarray], np.ndarray],
    peaks: np.ndarray,
    values: np.ndarray | None = None,
) -> None:
    """Raise ``peaks`` (npk,) to the continuous peaks of ``quantities(t, y)`` (npk,) over the
    steps ending at ``ts`` (ascending, the first the segment's start) of the dense output
    ``dense(t)`` (the state y at t; scipy's ``OdeSolution``). ``values`` (nts, npk): the
    quantities at ``ts`` where the caller has them already (default: evaluated here); a NaN
    column is not tracked."""
    ts = np.asarray(ts, dtype=float)
    if len(ts) == 0:
        return
    if values is None:
        values = np.array([quantities(float(t), dense(float(t))) for t in ts])  # (nts, npk)
    n, npk = values.shape
    for k in range(npk):
        f = values[:, k]
        if not np.isfinite(f).any():
            continue
        peaks[k] = max(peaks[k], float(np.nanmax(f)))
        for i in range(n):
            left = f[i - 1] if i > 0 else -np.inf
            right = f[i + 1] if i < n - 1 else -np.inf
            if not (f[i] >= left and f[i] >= right) or (f[i] == left and f[i] == right):
                continue  # not a local maximum of the step ends (or a plateau, e.g. 0)
            lo, hi = ts[max(i - 1, 0)], ts[min(i + 1, n - 1)]
            if not hi > lo:
                continue

            def negative(t: float, k: int = k) -> float:
                return -float(quantities(t, dense(t))[k])

            from scipy.optimize import minimize_scalar  # here: see the module's docstring

            found = minimize_scalar(
                negative, bounds=(lo, hi), method="bounded",
                options={"xatol": LOCATE_XATOL * (hi - lo)},
            )  # fmt: skip
            if np.isfinite(found.fun):
                peaks[k] = max(peaks[k], -float(found.fun))
