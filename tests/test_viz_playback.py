"""``mcchain show``: the .rrd it saves, read back with rerun 0.41's chunk reader.

rerun 0.41 reads a recording with ``rerun.chunk.RrdReader(path).stream()``: chunks with an
entity path, a static flag and an Arrow record batch (``time`` as duration[ns], one column per
component). (``rerun.dataframe`` is gone in 0.41 and ``ChunkStore.reader`` needs datafusion,
which is not a dependency.)
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pytest
import xarray as xr
from test_viz_synthetic import make_dataset, make_model, random_params

from mcchain import cli
from mcchain.cli import parser as parser_module
from mcchain.ensemble import queries
from mcchain.errors import RunError
from mcchain.viz import geometry, live, playback, show

FLOAT32 = 1e-6  # relative round-off of positions, which rerun stores as float32
OFFSET_FROM_FLOAT32 = 4 * 2.0**-24 * 2.0  # |d| from float32 positions of ~1 m (m, unmagnified)
NSAMPLE, NTIME = 5, 40


# -- reading an .rrd back ------------------------------------------------------------------------
def read_rrd(path: Path) -> dict[str, dict[str, Any]]:
    """entity path -> {"static": {component: value}, "time": ns (n,), component: [rows]}."""
    from rerun.chunk import RrdReader

    entities: dict[str, dict[str, Any]] = {}
    temporal: dict[str, list[pa.RecordBatch]] = {}
    for chunk in RrdReader(path).stream():
        entry = entities.setdefault(chunk.entity_path, {"static": {}})
        batch = chunk.to_record_batch()
        if chunk.is_static:
            for name in batch.schema.names:
                if ":" in name:
                    entry["static"][name] = batch.column(name).to_pylist()[-1]
        elif "time" in batch.schema.names:
            temporal.setdefault(chunk.entity_path, []).append(batch)
    for path_, batches in temporal.items():
        table = pa.Table.from_batches(batches, schema=batches[0].schema)
        time = np.asarray(table.column("time").cast(pa.int64()).to_numpy())
        order = np.argsort(time, kind="stable")
        entry = entities[path_]
        entry["time"] = time[order]
        for name in table.schema.names:
            if ":" in name:
                rows = table.column(name).to_pylist()
                entry[name] = [rows[i] for i in order]
    return entities


def _arr(rows: list[Any]) -> np.ndarray:
    return np.array(rows, dtype=np.float64)


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory: pytest.TempPathFactory) -> tuple[xr.Dataset, Any]:
    """A lazily opened netCDF ensemble (as ``open_run`` gives) and its model."""
    params = random_params(NSAMPLE)
    path = tmp_path_factory.mktemp("run") / "ensemble.nc"
    make_dataset(params, ntime=NTIME).to_netcdf(path)
    return xr.open_dataset(path), make_model(params)


@pytest.fixture(scope="module")
def saved(
    synthetic: tuple[xr.Dataset, Any], tmp_path_factory: pytest.TempPathFactory
) -> tuple[Path, dict[str, dict[str, Any]]]:
    """``mcchain show RUN --samples 0,1 --save FILE`` on the synthetic run, read back."""
    ds, model = synthetic
    out = tmp_path_factory.mktemp("show") / "sub" / "show.rrd"
    mp = pytest.MonkeyPatch()
    mp.setattr(show, "open_inputs", lambda run: (ds, model))
    try:
        assert cli.main(["show", "RUN", "--samples", "0,1", "--save", str(out)]) == 0
    finally:
        mp.undo()
    return out, read_rrd(out)


# -- the recording -------------------------------------------------------------------------------
def test_show__rrd_holds_the_expected_entity_paths(saved: Any) -> None:
    path, rrd = saved
    per_sample = {
        "info",
        "mechanism/ground",
        "mechanism/bodies",
        "mechanism/centres",
        "mechanism/joints",
        "mechanism/forces",
        "mechanism/clearance/journal",
        "mechanism/clearance/offset",
        "mechanism/clearance/bearing",
        "orbit/O/circle",
        "orbit/O/path",
        "orbit/O/journal",
        "joint_force/O",
        "joint_force/A",
        "contact_force/O",
        "energy",
        "constraint_error",
    }
    expected = {f"/sample/{s}/{p}" for s in (0, 1) for p in per_sample}
    found = {p for p in rrd if p.startswith("/sample/")}
    assert found == expected
    # no contact force plot for the ideal joint A; static entities have no timeline
    assert "/sample/0/contact_force/A" not in rrd
    for p in ("info", "mechanism/ground"):
        assert "time" not in rrd[f"/sample/0/{p}"] and rrd[f"/sample/0/{p}"]["static"]
    from rerun.chunk import RrdReader

    assert RrdReader(path).blueprints(), "the default blueprint is saved with the recording"


def test_show__every_series_has_one_row_per_time_point(saved: Any, synthetic: Any) -> None:
    _, rrd = saved
    ds, _ = synthetic
    time_ns = np.round(ds["time"].values * 1e9).astype(np.int64)
    for path, entry in rrd.items():
        if "time" in entry:
            assert len(entry["time"]) == NTIME, path
            np.testing.assert_array_equal(entry["time"], time_ns, err_msg=path)


def test_show__scalar_values_equal_the_ensemble(saved: Any, synthetic: Any) -> None:
    _, rrd = saved
    ds, _ = synthetic
    for s in (0, 1):
        for k, joint in enumerate(("O", "A")):
            got = _arr(rrd[f"/sample/{s}/joint_force/{joint}"]["Scalars:scalars"])
            want = ds["joint_force"].values[s, :, k, :].astype(np.float64)
            np.testing.assert_array_equal(got, want)
            names = rrd[f"/sample/{s}/joint_force/{joint}"]["static"]["SeriesLines:names"]
            assert names == ["x", "y"]
        got = _arr(rrd[f"/sample/{s}/contact_force/O"]["Scalars:scalars"])[:, 0]
        np.testing.assert_array_equal(got, ds["contact_force"].values[s, :, 0])
        for name in ("energy", "constraint_error"):
            got = _arr(rrd[f"/sample/{s}/{name}"]["Scalars:scalars"])[:, 0]
            np.testing.assert_array_equal(got, ds[name].values[s])


def test_show__mechanism_is_drawn_where_the_ensemble_puts_it(saved: Any, synthetic: Any) -> None:
    _, rrd = saved
    ds, model = synthetic
    scale = playback.default_force_scale(ds, model, [0, 1])
    for s in (0, 1):
        q = ds["q"].values[s].astype(np.float64)
        jt = geometry.joint_track(model, s, q, playback.DEFAULT_MAGNIFY)
        flip = np.array([1.0, -1.0])  # rerun 2D views are y-down
        joints = _arr(rrd[f"/sample/{s}/mechanism/joints"]["Points2D:positions"])
        np.testing.assert_allclose(joints, jt.bearing * flip, rtol=FLOAT32, atol=FLOAT32)
        centres = _arr(rrd[f"/sample/{s}/mechanism/centres"]["Points2D:positions"])
        np.testing.assert_allclose(centres, q[:, :, :2] * flip, rtol=FLOAT32, atol=FLOAT32)
        forces = rrd[f"/sample/{s}/mechanism/forces"]
        vectors = _arr(forces["Arrows2D:vectors"])
        want = ds["joint_force"].values[s].astype(np.float64) * scale * flip
        np.testing.assert_allclose(vectors, want, rtol=FLOAT32, atol=FLOAT32)
        np.testing.assert_allclose(
            _arr(forces["Arrows2D:origins"]), jt.drawn * flip, rtol=FLOAT32, atol=FLOAT32
        )
        # the clearance offset: from the bearing, magnify * c long
        offset = _arr(rrd[f"/sample/{s}/mechanism/clearance/offset"]["Arrows2D:vectors"])
        c = ds["parameters"].values[s, 0]
        np.testing.assert_allclose(
            np.linalg.norm(offset[:, 0], axis=1) / playback.DEFAULT_MAGNIFY,
            c,
            atol=OFFSET_FROM_FLOAT32,
        )
        # one strip per body per frame, through the body's points
        bodies = rrd[f"/sample/{s}/mechanism/bodies"]
        assert all(len(frame) == model.nbody for frame in bodies["LineStrips2D:strips"])
        assert bodies["static"]["LineStrips2D:labels"] == ["crank", "bar"]
        bar = _arr([frame[1] for frame in bodies["LineStrips2D:strips"]])  # (time, point, xy)
        local = geometry.body_outlines(model, s)[1].strips[0]
        want = geometry.to_world(local, q[:, 1]) * flip
        np.testing.assert_allclose(bar, want, rtol=FLOAT32, atol=FLOAT32)


def test_show__equilibrium_only_run_is_one_frame_at_zero(tmp_path: Path) -> None:
    params = random_params(3)
    ds = make_dataset(params, history=False)
    model = make_model(params)
    out = tmp_path / "eq.rrd"
    show.show(ds, model, [0], save=out)
    rrd = read_rrd(out)
    force = rrd["/sample/0/joint_force/O"]
    np.testing.assert_array_equal(force["time"], [0])
    np.testing.assert_array_equal(_arr(force["Scalars:scalars"])[0], ds["joint_force_eq"][0, 0])
    assert "/sample/0/energy" not in rrd


def test_log_samples__a_chunk_model_with_offset_draws_the_same(
    synthetic: Any, tmp_path: Path
) -> None:
    """Live streaming logs a chunk with ``model.select(start, stop)``: same pictures."""
    ds, model = synthetic
    files = []
    for name, mdl, offset in (("whole", model, 0), ("chunk", model.select(2, 5), 2)):
        files.append(tmp_path / f"{name}.rrd")
        rec = playback.open_recording(save=files[-1])
        with rec:
            playback.log_samples(
                ds.isel(sample=slice(2, 5)), mdl, [3], rec, force_scale=0.01, model_offset=offset
            )
    whole, chunk = (read_rrd(f) for f in files)
    for path in ("mechanism/bodies", "mechanism/clearance/bearing"):
        entity = f"/sample/3/{path}"
        assert whole[entity]["LineStrips2D:strips"] == chunk[entity]["LineStrips2D:strips"]


# -- choosing samples ----------------------------------------------------------------------------
def test_select_samples__worst_status_and_explicit(synthetic: Any) -> None:
    ds, _ = synthetic
    cf = np.abs(ds["contact_force"].values.astype(np.float64))
    peak = np.nanmax(cf.reshape(NSAMPLE, -1), axis=1)
    worst2 = [int(i) for i in np.argsort(-peak, kind="stable")[:2]]
    assert queries.select_samples(ds, worst="contact_force:2") == worst2
    assert queries.select_samples(ds, status="contact_lost") == [1]
    assert queries.select_samples(ds, status="ok", limit=2) == [0, 3]
    assert queries.select_samples(ds, status="contact_lost", worst="energy:3") == [1]
    assert queries.select_samples(ds, [4], status="contact_lost") == [4, 1]
    assert queries.select_samples(ds) == [0]
    # peak |omega| skips the sample whose equilibrium failed (all NaN)
    assert 2 not in queries.select_samples(ds, worst=f"omega:{NSAMPLE}")


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"samples": [7]}, "--samples: 7 is not a sample"),
        ({"worst": "contact_force"}, "--worst: expected VARIABLE:N"),
        ({"worst": "contact_force:0"}, "--worst: N must be >= 1"),
        ({"worst": "nothing:2"}, "--worst: no per-sample variable 'nothing'"),
        ({"status": "lost"}, "--status: unknown flag 'lost'"),
        ({"status": "diverged"}, "no sample matches diverged"),
    ],
)
def test_select_samples__bad_criteria_name_the_flag(
    synthetic: Any, kwargs: dict[str, Any], message: str
) -> None:
    ds, _ = synthetic
    with pytest.raises(RunError, match=message):
        queries.select_samples(ds, **kwargs)


def test_parse_samples__integers_only() -> None:
    assert queries.parse_samples("0,17,0") == [0, 17]
    with pytest.raises(RunError, match="--samples"):
        queries.parse_samples("0,a")


def test_show_command__usage_error_is_one_line_naming_the_command(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert cli.main(["show", "RUN", "--bogus"]) == 2
    assert capsys.readouterr().err == (
        "mcchain: error: mcchain show: unrecognized arguments: --bogus\n"
    )
    assert cli.main(["show", "RUN", "--save", "x.rrd", "--spawn"]) == 2
    assert "mcchain show: argument --spawn: not allowed with" in capsys.readouterr().err


def test_show__without_a_display_the_viewer_is_refused_before_anything_starts(
    synthetic: tuple[xr.Dataset, Any],
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """On a headless Linux machine the spawned viewer dies and its recording is lost: the
    default sink (and --rerun-spawn of a run) is refused in one line naming what to use."""
    ds, model = synthetic
    for name in ("DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET"):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setattr(show.sys, "platform", "linux")
    monkeypatch.setattr(show, "open_inputs", lambda run: (ds, model))
    spawned: list[Any] = []
    monkeypatch.setattr("rerun.script_setup", lambda *a, **k: spawned.append(a))
    assert cli.main(["show", "RUN", "--samples", "0"]) == 2
    out, err = capsys.readouterr()
    assert out == "" and spawned == []
    assert err.startswith("mcchain: error: show: no display to open the rerun viewer on")
    assert "--save FILE.rrd" in err and len(err.strip().splitlines()) == 1
    assert cli.main(["run", "SCENE.toml", "--rerun", "0", "--rerun-spawn"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("mcchain: error: --rerun-spawn: no display") and spawned == []
    monkeypatch.setenv("DISPLAY", ":0")
    assert show.viewer_cannot_spawn("show") is None


def show_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser()
    parser_module.add_show_arguments(parser)
    return parser


def test_show_arguments__cover_rerun_script_flags() -> None:
    """``rr.script_setup`` reads the flags ``rr.script_add_args`` declares; ours has them all."""
    import rerun as rr

    theirs = argparse.ArgumentParser()
    rr.script_add_args(theirs)
    ours = show_parser()
    assert {a.dest for a in theirs._actions} <= {a.dest for a in ours._actions}
    args = ours.parse_args(["RUN", "--samples", "0,17", "--magnify", "50"])
    assert args.magnify == 50.0 and args.samples == "0,17" and not args.spawn
    assert ours.parse_args(["RUN"]).magnify == playback.DEFAULT_MAGNIFY == 100.0


# -- live streaming ------------------------------------------------------------------------------
def test_live_stream__chunks_built_by_the_registry_are_logged_as_show_logs_them(
    synthetic: Any, tmp_path: Path
) -> None:
    """``mcchain run --rerun 1,3``: each chunk's Dataset (``build_dataset``) and model."""
    from mcchain.ensemble.registry import build_dataset

    ds, model = synthetic
    whole = ds.load()
    out = tmp_path / "live.rrd"
    with live.LiveStream([3, 1], save=out, force_scale=0.01) as stream:
        for start, stop in ((0, 2), (2, 4), (4, NSAMPLE)):
            part = whole.isel(sample=slice(start, stop))
            outputs = {name: part[name].values for name in part.data_vars}
            outputs["time"] = part["time"].values
            chunk = build_dataset(outputs, model.select(start, stop), start=start)
            logged = stream.log_chunk(chunk, model.select(start, stop), start)
            assert logged == [s for s in (1, 3) if start <= s < stop]
    rrd = read_rrd(out)
    assert {p.split("/")[2] for p in rrd if p.startswith("/sample/")} == {"1", "3"}
    from rerun.chunk import RrdReader

    assert RrdReader(out).blueprints()
    for s in (1, 3):
        got = _arr(rrd[f"/sample/{s}/joint_force/O"]["Scalars:scalars"])
        np.testing.assert_array_equal(got, whole["joint_force"].values[s, :, 0])
        jt = geometry.joint_track(model, s, whole["q"].values[s].astype(float), 100.0)
        offset = _arr(rrd[f"/sample/{s}/mechanism/clearance/offset"]["Arrows2D:vectors"])[:, 0]
        np.testing.assert_allclose(offset, (jt.drawn - jt.bearing)[:, 0] * [1, -1], rtol=FLOAT32)
