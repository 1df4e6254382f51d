"""Report figure of the modes along a driver's turn (``[modes] along``): a Campbell-style chart.

==============================  ==========================================================
``modes_along_cycle.png``       natural frequencies f = ω/2π (Hz) of the mechanism frozen
                                along one turn of the driver, against the driver's angle:
                                per mode the median over the samples and its 5–95 % band;
                                horizontal lines at the harmonics k·f_drive of the drive
                                speed (where a mode meets one, the drive excites it:
                                resonance), labelled, with the crossings marked
==============================  ==========================================================
"""

from __future__ import annotations

import json
from typing import TYPE_CHECKING, Any

import numpy as np

from mcchain.viz.figures import figure, panel_title

if TYPE_CHECKING:
    import xarray as xr
    from matplotlib.figure import Figure

MAX_HARMONICS = 12
"""Most harmonic lines drawn (more below the modes' top: none, the ratio is said instead)."""


def along_driver(ds: xr.Dataset) -> tuple[str, float] | None:
    """The driver followed by ``[modes] along`` and its speed ω (rad/s: the median over the
    samples when it is sampled), from the run's settings; None if the run has none."""
    try:
        scene: dict[str, Any] = json.loads(ds.attrs["settings"])["scene"]
        body = scene["modes"]["along"]["driver"]
        omega = next(float(d["omega"]) for d in scene["driver"] if d["body"] == body)
    except (KeyError, TypeError, StopIteration, ValueError):
        return None
    path = f"driver.{body}.omega"
    if "param" in ds.coords and path in [str(p) for p in ds["param"].values]:
        omega = float(np.nanmedian(ds["parameters"].sel(param=path).values))
    return body, omega


def campbell_figure(ds: xr.Dataset) -> Figure | str:
    """The figure of ``modes_along_cycle.png``, or why there is none."""
    if "omega_cycle" not in ds.data_vars:
        return "the run has no modes along a cycle ([modes] along)"
    found = along_driver(ds)
    if found is None:
        return "the run's settings do not name the driver of [modes] along"
    body, drive = found
    freq = np.asarray(ds["omega_cycle"].transpose("sample", "phase", "mode").values, float)
    freq = freq / (2.0 * np.pi)
    angle = np.degrees(np.asarray(ds["phase"].values, float))
    fig, axes = figure(1, 1, w=7.0, h=4.2)
    ax = axes[0, 0]
    finite = np.isfinite(freq)
    if not finite.any():
        ax.text(0.5, 0.5, "no configuration could be assembled", ha="center",
                transform=ax.transAxes)  # fmt: skip
        return fig
    nsample, _, nmode = freq.shape
    for k in range(nmode):
        values = freq[:, :, k]
        keep = np.isfinite(values).any(axis=0)
        with np.errstate(all="ignore"):
            lo, mid, hi = np.nanpercentile(values[:, keep], [5.0, 50.0, 95.0], axis=0)
        ax.fill_between(angle[keep], lo, hi, color=f"C{k}", alpha=0.25, linewidth=0)
        ax.plot(angle[keep], mid, color=f"C{k}", label=f"mode {k}")
    f_drive = abs(drive) / (2.0 * np.pi)
    with np.errstate(all="ignore"):
        median = np.nanmedian(freq, axis=0)
    lowest = float(np.nanmin(median))
    top = float(np.nanmax(freq))
    if f_drive > 0.0:
        count = int(np.floor(top / f_drive))
        ratio = lowest / f_drive
        if 1 <= count <= MAX_HARMONICS:
            for h in range(1, count + 1):
                ax.axhline(h * f_drive, color="0.5", linewidth=0.6, linestyle="--")
                ax.annotate(f"{h}×", (angle[0], h * f_drive), fontsize=7, color="0.35",
                            xytext=(2, 2), textcoords="offset points")  # fmt: skip
            crossings = _crossings(angle, median, f_drive, 1, count)
            if crossings:
                ax.plot(*zip(*crossings, strict=True), "kx", markersize=6,
                        label="median meets a harmonic: resonance")  # fmt: skip
            note = f"drive {f_drive:.3g} Hz ({drive:.4g} rad/s), harmonics dashed"
        else:
            note = (
                f"drive {f_drive:.3g} Hz ({drive:.4g} rad/s): the lowest median, "
                f"{lowest:.4g} Hz, is {ratio:.3g}× the drive"
                + (" (harmonics not drawn: too many below the modes)" if count else "")
            )
    else:
        note = "the driver does not turn (ω = 0): no harmonics"
    ax.set_xlabel(f"angle of driver {body} from its angle0 [°]")
    ax.set_ylabel("natural frequency f [Hz]")
    ax.set_xlim(angle[0], angle[0] + 360.0)
    title = f"modes along one turn of {body}, {nsample} samples: median, 5–95 %; {note}"
    panel_title(ax, title)
    ax.legend(fontsize=7, frameon=False, loc="best")
    ax.secondary_yaxis(
        "right", functions=(lambda f: 2.0 * np.pi * f, lambda w: w / (2.0 * np.pi))
    ).set_ylabel("ω [rad/s]")
    return fig


def _crossings(
    angle: np.ndarray, median: np.ndarray, f_drive: float, first: int, last: int
) -> list[tuple[float, float]]:
    """(angle, frequency) where a mode's median curve crosses a drawn harmonic (linear
    interpolation between configurations)."""
    points = []
    for k in range(median.shape[1]):
        curve = median[:, k]
        for h in range(first, last + 1):
            level = h * f_drive
            side = curve - level
            for j in np.flatnonzero(np.isfinite(side[:-1]) & np.isfinite(side[1:])):
                if side[j] == 0.0 or side[j] * side[j + 1] < 0.0:
                    w = side[j] / (side[j] - side[j + 1]) if side[j] != side[j + 1] else 0.0
                    points.append((float(angle[j] + w * (angle[j + 1] - angle[j])), level))
    return points
