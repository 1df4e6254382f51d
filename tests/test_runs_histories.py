"""Light runs: ``[storage] histories = "all" | "none" | "failed"``, end to end.

The scene is the turning clearance bar of the extend tests with a requirement on its peak
pin force whose limit lies inside the sampled spread, so that some samples fail it and
some meet it: the ``"failed"`` subset is then neither empty nor everything, and every
comparison below could fail.
"""

from __future__ import annotations

import filecmp
import json
from pathlib import Path

import netCDF4
import numpy as np
import pytest
import xarray as xr

from mcchain.ensemble.export import STORED_PREFIX, sample_table
from mcchain.ensemble.histories import (
    HISTORY_SAMPLE,
    history_names,
    replay_mask,
    sample_history,
    stored_mode,
)
from mcchain.ensemble.io import list_parts
from mcchain.ensemble.registry import validate_dataset
from mcchain.errors import RunError
from mcchain.runner import plan, runs
from mcchain.runner.resources import stored_sample_bytes
from mcchain.scene import compile_model, load_scene
from mcchain.testing.scenes import hanging_clearance_bar_text

LIMIT = 780.0
"""N: the peak pin force limit, inside the spread of the 24 samples' peaks (the journal
rattles in its bearing: 518-1367 N; 5 samples diverge), so some fail and some meet it."""


def scene_text(histories: str, count: int = 24) -> str:
    return (
        hanging_clearance_bar_text("light-bar", angular_velocity=1.0)
        + f"""[equilibrium]
[modes]
[simulate]
t_end = 0.02
dt = 1e-4
method = "rk4"
output_dt = 1e-3
[storage]
histories = "{histories}"
[sample]
count = {count}
seed = 11
[sample.vary]
"joint.O.clearance" = {{ uniform = [1e-4, 1e-3] }}
"body.bar.mass" = {{ normal = [2.0, 0.02] }}
[[requirement]]
name = "pin"
output = "peak_joint_force"
select = {{ joint = "O" }}
max = {LIMIT}
"""
    )


def write_scene(folder: Path, histories: str, count: int = 24) -> Path:
    path = folder / f"{histories}.toml"
    path.write_text(scene_text(histories, count), encoding="utf-8")
    return path


def run(folder: Path, histories: str, name: str, **options: object) -> Path:
    options = {"chunk_size": 10, "threads": 1, **options}
    return plan.start_run(
        write_scene(folder, histories),
        run_dir=folder / name,
        progress=False,
        **options,  # type: ignore[arg-type]
    ).folder


def same_bits(a: np.ndarray, b: np.ndarray, name: str) -> None:
    assert a.dtype == b.dtype and a.shape == b.shape, name
    np.testing.assert_array_equal(
        np.ascontiguousarray(a).view(np.uint8), np.ascontiguousarray(b).view(np.uint8), name
    )


@pytest.fixture(scope="module")
def three(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The same 24 samples stored with each value of ``histories``."""
    folder = tmp_path_factory.mktemp("light")
    return {mode: run(folder, mode, mode) for mode in ("all", "none", "failed")}


def test_histories__none_keeps_every_per_sample_variable_bit_for_bit(three) -> None:
    with runs.open_run(three["all"]) as full, runs.open_run(three["none"]) as light:
        validate_dataset(light)
        assert stored_mode(full) == "all" and stored_mode(light) == "none"
        histories = set(history_names(full))
        assert {"q", "joint_force", "energy", "constraint_error"} <= histories
        assert not set(history_names(light)) and "time" not in light.variables
        assert set(light.data_vars) == set(full.data_vars) - histories
        for name in light.variables:
            same_bits(light[name].values, full[name].values, str(name))
        assert json.loads(light.attrs["settings"])["scene"]["storage"]["histories"] == "none"
    # (the slider-crank's sizes: benchmarks/bench_light.py; here headers dominate)
    size = {mode: (three[mode] / "ensemble.nc").stat().st_size for mode in ("all", "none")}
    assert size["none"] < size["all"]


def test_histories__failed_keeps_those_of_the_failing_samples(three) -> None:
    with runs.open_run(three["all"]) as full, runs.open_run(three["failed"]) as light:
        validate_dataset(light)
        met = full.requirement_met.values
        status = full.status.values
        expected = np.flatnonzero((met == 0).any(axis=1) | (status != 0))
        assert 0 < expected.size < full.sizes["sample"]  # the limit splits the samples
        np.testing.assert_array_equal(expected, replay_mask(status, met).nonzero()[0])
        np.testing.assert_array_equal(light[HISTORY_SAMPLE].values, expected)
        for name in history_names(full):
            assert light[name].dims == (HISTORY_SAMPLE, *full[name].dims[1:])
            stored = light[name].values
            same_bits(stored, full[name].isel(sample=expected).values, name)
        for name in set(light.variables) - set(history_names(light)) - {HISTORY_SAMPLE}:
            same_bits(light[name].values, full[name].values, str(name))
        s = int(expected[0])
        same_bits(sample_history(light, "q", s).values, full.q.sel(sample=s).values, "q")
        kept = set(expected.tolist())
        other = next(i for i in range(full.sizes["sample"]) if i not in kept)
        with pytest.raises(RunError, match=rf"sample {other}: time history not stored"):
            sample_history(light, "q", other)


def test_histories__byte_identical_whatever_the_chunks_and_threads(tmp_path: Path, three) -> None:
    for mode in ("none", "failed"):
        other = run(tmp_path, mode, f"{mode}-chunks", chunk_size=7, threads=2)
        assert filecmp.cmp(three[mode] / "ensemble.nc", other / "ensemble.nc", shallow=False)


@pytest.mark.slow
def test_histories__byte_identical_on_dask(tmp_path: Path, three, dask_scheduler: str) -> None:
    """Both on one Dask cluster of two process workers (conftest's ``dask_scheduler``)."""
    for mode in ("none", "failed"):
        other = run(tmp_path, mode, f"{mode}-dask", chunk_size=5, dask=dask_scheduler)
        assert filecmp.cmp(three[mode] / "ensemble.nc", other / "ensemble.nc", shallow=False)


def test_histories__failed_run_extended_equals_one_run(tmp_path: Path, three) -> None:
    """``--extend`` merges the stored subset of the first samples with the new ones'."""
    small = plan.start_run(
        write_scene(tmp_path, "failed"), samples=13, chunk_size=10, threads=1,
        run_dir=tmp_path / "small", progress=False,
    ).folder  # fmt: skip
    plan.extend_run(small, 11, progress=False, threads=1)
    with runs.open_run(small) as extended, runs.open_run(three["failed"]) as whole:
        assert set(extended.variables) == set(whole.variables)
        for name in whole.variables:
            same_bits(extended[name].values, whole[name].values, str(name))


def test_histories__disk_estimate_counts_what_is_stored(tmp_path: Path) -> None:
    """Bytes per sample of the part files: the estimate of ``"none"`` is exact; of
    ``"failed"`` an upper bound that the histories of every sample reach."""
    sizes = {}
    for mode in ("all", "none", "failed"):
        path = write_scene(tmp_path, mode)
        scene = load_scene(path)
        sizes[mode] = stored_sample_bytes(scene, compile_model(scene, nsample=24))
    assert sizes["none"] < sizes["all"] < sizes["failed"] == sizes["all"] + 8
    folder = run(tmp_path, "none", "parts", keep_parts=True)
    for part in list_parts(folder / "parts"):
        with netCDF4.Dataset(part.path) as nc:
            data = sum(
                v.size * v.dtype.itemsize
                for v in nc.variables.values()
                if "sample" in v.dimensions and v.name != "requirement_met"
            )
        assert data == sizes["none"] * (part.stop - part.start)


def test_histories__export_has_no_stored_maxima_of_a_light_run(three) -> None:
    with runs.open_run(three["all"]) as full, runs.open_run(three["failed"]) as light:
        whole, table = sample_table(full), sample_table(light)
    assert any(c.startswith(STORED_PREFIX) for c in whole.columns)
    kept = [c for c in whole.columns if not c.startswith(STORED_PREFIX)]
    assert list(table.columns) == kept
    for column in kept:
        assert whole[column].equals(table[column]), column


def test_histories__report_says_the_history_figures_are_not_stored(three, tmp_path) -> None:
    from mcchain.viz.report_page import write_report

    for mode in ("none", "failed"):
        report = write_report(three[mode], tmp_path / mode)
        for figure in ("reaction_envelopes.png", "journal_orbit.png"):
            assert report.skipped[figure].startswith("histories not stored"), figure
        assert (tmp_path / mode / "omega_histogram.png").is_file()
        page = (tmp_path / mode / "index.html").read_text()
        assert "histories not stored" in page


def test_histories__show_replays_a_stored_history_and_names_a_missing_one(three, tmp_path):
    from mcchain.viz.show import show_run

    with runs.open_run(three["failed"]) as light:
        kept = light[HISTORY_SAMPLE].values.tolist()
    missing = next(i for i in range(24) if i not in kept)
    target = tmp_path / "kept.rrd"
    assert show_run(three["failed"], [kept[0]], save=target) == [kept[0]]
    assert target.stat().st_size > 0
    with pytest.raises(RunError, match=rf"sample {missing}: time history not stored"):
        show_run(three["failed"], [missing], save=tmp_path / "missing.rrd")
    with pytest.raises(RunError, match='histories = "none"'):
        show_run(three["none"], [0], save=tmp_path / "none.rrd")
    with pytest.raises(RunError, match="--worst: contact_force: histories not stored"):
        show_run(three["none"], worst="contact_force:1", save=tmp_path / "worst.rrd")


def test_histories__bad_value_is_one_line_exit_2_nothing_written(tmp_path: Path, mcchain) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(scene_text("all").replace('histories = "all"', 'histories = "some"'))
    proc = mcchain("run", path, "--out", tmp_path / "runs", cwd=tmp_path)
    assert proc.returncode == 2 and proc.stdout == ""
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "storage.histories" in lines[0] and "some" in lines[0], lines
    assert not (tmp_path / "runs").exists()


def test_histories__failed_dataset_reads_back_lazily(three) -> None:
    """xarray opens the subset as its own dimension; its coordinate is the sample index."""
    ds = xr.open_dataset(three["failed"] / "ensemble.nc")
    try:
        assert ds[HISTORY_SAMPLE].attrs["long_name"].startswith("global sample index")
        assert ds.q.dims[0] == HISTORY_SAMPLE
    finally:
        ds.close()


def test_histories__check_of_a_light_run_equals_the_full_runs(three) -> None:
    """``mcchain check`` re-solves the samples itself: a light run's check is the full
    run's (it compares per-sample variables only)."""
    from mcchain.decision.check import check_run

    full, light = check_run(three["all"]), check_run(three["failed"])
    assert [r.requirement for r in full.rows] == [r.requirement for r in light.rows] == ["pin"]
    assert full.lines() == light.lines()


@pytest.mark.parametrize(("limit", "kept"), [(1e9, 0), (1.0, 4)])
def test_histories__failed_with_no_failure_and_with_all_failing(tmp_path, limit, kept) -> None:
    """The edges: the first 4 samples carry no status flag; a limit none reaches keeps no
    history (an empty history_sample), one every sample exceeds keeps them all."""
    path = tmp_path / "edge.toml"
    path.write_text(scene_text("failed").replace(f"max = {LIMIT}", f"max = {limit}"))
    folder = plan.start_run(
        path, samples=4, chunk_size=3, threads=1, run_dir=tmp_path / "edge", progress=False
    ).folder
    with runs.open_run(folder) as ds:
        validate_dataset(ds)
        assert (ds.status.values == 0).all()
        assert ds.sizes[HISTORY_SAMPLE] == kept and ds.q.shape[0] == kept
        assert stored_mode(ds) == "failed"
        if kept:
            same_bits(ds[HISTORY_SAMPLE].values, np.arange(4, dtype=np.int64), "kept")
        else:
            with pytest.raises(RunError, match="sample 2: time history not stored"):
                sample_history(ds, "q", 2)


@pytest.mark.parametrize(
    "method",
    ["rk45", "rk4", "rk4-loop", "rk4-projection", "generalized-alpha", "radau"],
)
def test_simulate__without_histories_every_per_sample_value_is_the_same(method) -> None:
    """``simulate(histories=False)`` (what ``"none"`` runs): the histories come back with 0
    times, nothing stored, and every per-sample value (status, peaks, contact summaries,
    outputs, step counts) is bitwise that of the run that stores them, on every path, with
    the pin's impacts and a sample failed on entry (its values NaN) in the batch."""
    from mcchain.scene import load_scene_text
    from mcchain.solvers.output_plan import output_plan
    from mcchain.solvers.simulate import simulate
    from mcchain.solvers.statics import assemble
    from mcchain.status import ASSEMBLY_FAILED
    from mcchain.testing.scenes import flores_pin_text, with_lines

    name, kernels = (method[:-5], "loop") if method.endswith("-loop") else (method, "auto")
    fixed = name != "rk45" and name != "radau"
    text = flores_pin_text(t_end=0.012, method=name, rtol=1e-8, atol=1e-11, output_dt=1e-4)
    text = with_lines(text, {"dt": f"dt = {1e-6 if fixed else 1e-7!r}"})
    text += '\n[[output]]\nname = "pin"\nof = "joint_force"\njoint = "B"\n'
    text += 'component = "magnitude"\nreduce = "max"\n'
    scene = load_scene_text(text)
    model = compile_model(scene, nsample=4)
    model = replace_clearances(model, [1e-4, 2e-4, 5e-4, 3e-4])
    sim = scene.simulate.model_copy(update={"kernels": kernels})
    start = assemble(model)
    status = start.status.copy()
    status[3] |= ASSEMBLY_FAILED
    plan = output_plan(scene.output, model, sim.t_end)
    runs = [
        simulate(model, sim, start.q, start.v, status=status.copy(), diagnostics=True,
                 outputs=plan, histories=histories)
        for histories in (True, False)
    ]  # fmt: skip
    full, light = runs
    assert set(full) == set(light)
    for key, value in full.items():
        if key == "time":
            assert light[key].shape == (0,)
        elif value.ndim >= 2 and value.shape[1] == len(full["time"]) and key in HISTORY_KEYS:
            assert light[key].shape == (value.shape[0], 0, *value.shape[2:]), key
        else:
            assert light[key].dtype == value.dtype and light[key].tobytes() == value.tobytes(), key
    assert np.isfinite(full["output_values"][:3]).all() and np.isnan(full["output_values"][3])


HISTORY_KEYS = frozenset(
    ("q", "v", "joint_force", "contact_force", "driver_torque", "driver_force", "joint_moment",
     "constraint_error", "energy", "penetration", "contact_mode")
)  # fmt: skip
"""The time histories :func:`mcchain.solvers.simulate.simulate` returns."""


def replace_clearances(model, clearances):
    """``model`` with the piston pin's clearance of each sample (m)."""
    from dataclasses import replace as replaced

    values = np.array(model.joint_clearance, dtype=float)
    values = np.broadcast_to(values, (len(clearances), values.shape[-1])).copy()
    values[:, model.joint_names.index("B")] = clearances
    return replaced(model, joint_clearance=values)


def test_histories__a_live_stream_gets_the_histories_that_none_does_not_store(tmp_path) -> None:
    """``--rerun`` on a ``"none"`` scene: the solver still computes the histories (the stream
    shows them), the store still drops them (``Job.histories`` stays ``"none"``)."""
    from mcchain.runner.job import prepare_job
    from mcchain.solvers import solve_chunk

    job = prepare_job(write_scene(tmp_path, "none", count=2))
    live = job.with_solved_histories()
    assert live.histories == "none" and live.scene.storage.histories == "all"
    assert live.settings == job.settings  # what the file says of the scene: unchanged
    assert (
        prepare_job(write_scene(tmp_path, "all", count=2)).with_solved_histories().histories
        == "all"
    )
    light, full = solve_chunk(job.model, job.scene), solve_chunk(live.model, live.scene)
    assert light["q"].shape[1] == 0 and full["q"].shape[1] == len(full["time"]) > 1
