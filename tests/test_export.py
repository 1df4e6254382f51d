"""``mcchain export RUN --csv``: one row per sample, every value equal to the ensemble's."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from test_cli_commands import assert_usage_error, in_process

import mcchain
from mcchain.testing.factory import write_scene
from mcchain.testing.scenes import fourbar_text

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A statics sweep (equilibria, modes) and a short four-bar history."""
    from mcchain.runner.plan import start_run

    out = tmp_path_factory.mktemp("runs")
    statics = start_run(REPO / "configs" / "clearance-sweep.toml", samples=64, out=out,
                        progress=False)  # fmt: skip
    text = fourbar_text() + (
        '[sample]\ncount = 6\nseed = 2\n[sample.vary]\n"joint.B.clearance" = '
        "{ uniform = [5e-5, 2e-4] }\n[simulate]\nt_end = 0.01\ndt = 1e-5\noutput_dt = 1e-3\n"
        # float64 histories, as test_simulate_accuracy's runs of the four-bar: their rk4
        # lane entry (an entry compiles per type of its arrays: float32 compiled the module
        # once more, 2.7 s cold); the export reads either type alike
        '[storage]\nhistory_dtype = "float64"\n'
    )
    scene = write_scene(tmp_path_factory.mktemp("scene"), text)
    history = start_run(scene, out=out, progress=False)
    return statics.folder, history.folder


def test_export__statics_columns_equal_the_ensemble(runs, tmp_path, monkeypatch, capsys):
    folder = runs[0]
    ran = in_process(monkeypatch, capsys)("export", folder, "--csv", cwd=tmp_path)
    assert ran.returncode == 0 and ran.stdout.strip() == str(folder / "export" / "samples.csv")
    table = pd.read_csv(folder / "export" / "samples.csv")
    ds = mcchain.open_run(folder)
    assert len(table) == 64 and list(table["sample"]) == list(range(64))
    np.testing.assert_array_equal(
        table["joint.O.clearance [m]"], ds.parameters.sel(param="joint.O.clearance")
    )
    for mode in range(ds.sizes["mode"]):
        omega = ds.omega.sel(mode=mode).values
        np.testing.assert_array_equal(table[f"omega_{mode} [rad s-1]"], omega)
        np.testing.assert_allclose(table[f"frequency_{mode} [Hz]"], omega / (2 * np.pi))
    np.testing.assert_array_equal(
        table["q_eq_bar_theta [rad]"], ds.q_eq.sel(body="bar", dof="theta")
    )
    assert set(table["status"]) <= {"ok", "contact_lost"}


def test_export__histories_become_their_largest_stored_values(runs, tmp_path):
    from mcchain.ensemble.export import export_run

    path = export_run(runs[1], tmp_path / "t.csv")
    table = pd.read_csv(path)
    ds = mcchain.open_run(runs[1])
    force = ds.joint_force.sel(joint="B").values
    expected = np.nanmax(np.hypot(force[..., 0], force[..., 1]), axis=1)
    np.testing.assert_allclose(table["max_stored_joint_force_B [N]"], expected, rtol=1e-7)
    torque = np.nanmax(np.abs(ds.driver_torque.sel(driver="crank").values), axis=1)
    np.testing.assert_allclose(table["max_stored_driver_torque_crank [N m]"], torque, rtol=1e-7)
    assert "max_stored_contact_force_O2 [N]" not in table  # an ideal joint has none
    assert "q_0_x" not in " ".join(table.columns)  # histories of positions stay in the ensemble
    # the continuous peaks (tracked at every step) are at least the stored points' largest
    assert (table["peak_joint_force_B [N]"] >= expected * (1 - 1e-6)).all()


def test_export__a_column_named_after_a_variable_is_that_variable(runs, tmp_path):
    """Every per-sample variable's column holds exactly its values (none is overwritten by
    a value reduced from the stored history), and no header appears twice."""
    from mcchain.ensemble.export import export_run

    path = export_run(runs[1], tmp_path / "t.csv")
    table = pd.read_csv(path)
    assert len(set(table.columns)) == len(table.columns)
    ds = mcchain.open_run(runs[1])
    checked = 0
    for name in ("peak_joint_force", "peak_driver_torque"):
        da = ds[name]
        units = da.attrs["units"]
        for label in [str(x) for x in da[da.dims[1]].values]:
            column = table[f"{name}_{label} [{units}]"].to_numpy()
            np.testing.assert_array_equal(column, da.sel({da.dims[1]: label}).values)
            checked += 1
    assert checked == ds.sizes["joint"] + ds.sizes["driver"]


def test_export__bad_arguments_are_one_line(runs, tmp_path, monkeypatch, capsys):
    run = in_process(monkeypatch, capsys)
    assert_usage_error(run("export", runs[0], cwd=tmp_path), "export: give the format: --csv")
    (tmp_path / "a-file").write_text("")
    ran = run("export", runs[0], "--csv", "--out", tmp_path / "a-file" / "x.csv", cwd=tmp_path)
    assert_usage_error(ran, "--out:", "is a file, not a folder")
    assert_usage_error(run("export", tmp_path / "nothing", "--csv", cwd=tmp_path), "nothing")


@pytest.fixture(scope="module")
def contact_sweep(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Three samples of the shipped contact sweep (configs/fourbar-contact-sweep.toml)."""
    from mcchain.runner.plan import start_run

    text = (REPO / "configs" / "fourbar-contact-sweep.toml").read_text()
    scene = write_scene(
        tmp_path_factory.mktemp("contact"), text.replace("count = 512", "count = 3")
    )
    return start_run(scene, out=tmp_path_factory.mktemp("runs"), progress=False).folder


def test_export__the_peak_contact_force_column_is_the_variable(contact_sweep, tmp_path):
    """On the shipped contact sweep the column ``peak_contact_force_B`` is the dataset's
    continuous peak bit for bit; the largest stored point has its own column, and is lower
    (the impacts' peaks fall between the stored points, every 1 ms)."""
    from mcchain.ensemble.export import export_run

    table = pd.read_csv(export_run(contact_sweep, tmp_path / "c.csv"))
    ds = mcchain.open_run(contact_sweep)
    peak = ds.peak_contact_force.sel(joint="B").values
    np.testing.assert_array_equal(table["peak_contact_force_B [N]"], peak)
    np.testing.assert_array_equal(
        table["peak_joint_force_B [N]"], ds.peak_joint_force.sel(joint="B")
    )
    stored = np.nanmax(ds.contact_force.sel(joint="B").values.astype(float), axis=1)
    np.testing.assert_allclose(table["max_stored_contact_force_B [N]"], stored, rtol=1e-7)
    assert (peak > stored).all()
    np.testing.assert_array_equal(ds.peak_joint_force.sel(joint="B").values, peak)
