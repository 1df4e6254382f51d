"""End to end: ``mcchain run`` a small clearance-bar sweep with ``[simulate]``, then
``mcchain show --save`` and ``mcchain report`` on the run folder it leaves.

The bar starts swinging about its pin (θ̇ = 2 rad/s with the centre of mass moving at
l θ̇ = 1 m/s, so the journal starts at rest in its bearing and stays in contact).

The integration kernels are compiled by numba for the scene's topology on first use (cached on
disk afterwards): the first run of this test on a machine takes minutes, later ones seconds.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_viz_playback import read_rrd
from test_viz_report import assert_real_picture

from mcchain import open_run
from mcchain.cli import main as cli
from mcchain.testing.scenes import hanging_clearance_bar_text

pytestmark = pytest.mark.slow

SCENE = (
    hanging_clearance_bar_text("clearance-bar-swing")
    + """
[equilibrium]
[modes]

[simulate]
t_end = 0.1
dt = 1e-3
output_dt = 5e-3
method = "rk4"
perturb = { "body.bar.angular_velocity" = 2.0, "body.bar.velocity[0]" = 1.0 }

[sample]
count = 8
seed = 11
design = "sobol"
[sample.vary]
"joint.O.clearance" = { uniform = [1e-4, 1e-3] }
"body.bar.mass" = { normal = [2.0, 0.02] }
"""
)


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("e2e")
    scene = folder / "clearance-bar-swing.toml"
    scene.write_text(SCENE)
    assert cli(["run", str(scene), "--run-dir", str(folder / "run"), "--quiet"]) == 0
    return folder / "run"


def test_e2e__show_saves_the_run_as_it_is_stored(run: Path, tmp_path: Path) -> None:
    out = tmp_path / "show.rrd"
    assert cli(["show", str(run), "--samples", "0,3", "--save", str(out)]) == 0
    ds = open_run(str(run))
    rrd = read_rrd(out)
    ntime = ds.sizes["time"]
    assert ntime == 21
    for s in (0, 3):
        for part in (
            "mechanism/bodies",
            "mechanism/joints",
            "mechanism/forces",
            "mechanism/clearance/offset",
            "joint_force/O",
            "contact_force/O",
            "energy",
            "constraint_error",
            "info",
        ):
            assert f"/sample/{s}/{part}" in rrd, part
        force = rrd[f"/sample/{s}/joint_force/O"]
        assert len(force["time"]) == ntime
        got = np.array(force["Scalars:scalars"], dtype=np.float64)
        want = ds["joint_force"].sel(sample=s).transpose("time", "joint", "xy").values[:, 0]
        np.testing.assert_array_equal(got, want.astype(np.float64))
        lam = np.array(rrd[f"/sample/{s}/contact_force/O"]["Scalars:scalars"], dtype=np.float64)
        np.testing.assert_array_equal(lam[:, 0], ds["contact_force"].sel(sample=s).values[:, 0])
        # the run is a meaningful one (not NaNs compared with NaNs): contact all along
        assert np.isfinite(got).all() and (lam > 0).all()


def test_e2e__report_writes_every_figure_the_run_allows(
    run: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert cli(["report", str(run)]) == 0
    written = {p.name for p in (run / "report").glob("*.png")}
    assert written == {
        "omega_histogram.png",
        "scatter_omega.png",
        "scatter_q_eq.png",
        "scatter_joint_force_eq.png",
        "scatter_peak_contact_force.png",
        "journal_orbit.png",
        "reaction_envelopes.png",
        "contact_loss.png",
        "status_counts.png",
    }
    for name in written:
        assert_real_picture(run / "report" / name)
    # 8 plain Sobol' points: no Saltelli rows and too few for RBD-FAST, and it says so
    assert "skipped sobol.png: 8 samples without Saltelli's layout" in capsys.readouterr().out
