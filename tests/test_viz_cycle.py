"""The Campbell-style chart of the modes along a driver's turn, on synthetic ensembles."""

from __future__ import annotations

import json
import re

import numpy as np
import xarray as xr
from test_viz_report import assert_texts_inside

from mcchain.viz.report_cycle import campbell_figure

DRIVE = 2 * np.pi * 10.0  # rad/s: a 10 Hz drive


def ensemble(mean_hz: float, swing_hz: float, nsample: int = 16, points: int = 36) -> xr.Dataset:
    """One mode whose frequency swings sinusoidally over the turn, samples scattered ±2 %."""
    phase = 2 * np.pi * np.arange(points) / points
    rng = np.random.default_rng(1)
    scale = 1.0 + 0.02 * rng.standard_normal((nsample, 1, 1))
    f = (mean_hz + swing_hz * np.sin(phase))[None, :, None] * scale
    settings = {"scene": {"driver": [{"body": "crank", "omega": DRIVE}],
                          "modes": {"along": {"driver": "crank", "points": points}}}}  # fmt: skip
    return xr.Dataset(
        {"omega_cycle": (("sample", "phase", "mode"), 2 * np.pi * f)},
        coords={"phase": phase},
        attrs={"settings": json.dumps(settings)},
    )


def test_campbell__harmonics_in_range_are_drawn_and_crossings_marked():
    fig = campbell_figure(ensemble(mean_hz=25.0, swing_hz=10.0))
    ax = fig.axes[0]
    dashed = [line for line in ax.get_lines() if line.get_linestyle() == "--"]
    assert [line.get_ydata()[0] for line in dashed] == [10.0, 20.0, 30.0]  # f up to 35.7 Hz
    crossings = [line for line in ax.get_lines() if line.get_marker() == "x"]
    assert len(crossings) == 1 and len(crossings[0].get_xdata()) == 4  # 20 Hz twice, 30 twice
    assert ax.get_xlabel() == "angle of driver crank from its angle0 [°]"
    assert ax.get_ylabel() == "natural frequency f [Hz]"
    assert "harmonics dashed" in " ".join(ax.get_title().split())
    assert_texts_inside(fig)


def test_campbell__modes_far_above_the_drive_say_the_ratio_instead():
    fig = campbell_figure(ensemble(mean_hz=400.0, swing_hz=50.0))
    ax = fig.axes[0]
    assert not [line for line in ax.get_lines() if line.get_linestyle() == "--"]
    title = ax.get_title().replace("\n", " ")
    assert re.search(r"the lowest median, 35\d\.\d Hz, is 35\.\d× the drive", title)


def test_campbell__a_run_without_modes_along_gets_a_reason():
    reason = campbell_figure(xr.Dataset())
    assert reason == "the run has no modes along a cycle ([modes] along)"
