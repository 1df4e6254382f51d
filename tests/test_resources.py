"""A run that cannot fit in memory is refused before anything is allocated or written."""

from __future__ import annotations

from pathlib import Path

import pytest
from test_cli_commands import assert_usage_error, in_process

from mcchain.scene import load_scene, memory
from mcchain.testing.factory import write_scene

REPO = Path(__file__).resolve().parents[1]
SWEEP = (REPO / "configs" / "clearance-sweep.toml").read_text()


def test_estimate__counts_the_sampled_arrays_per_sample() -> None:
    """Two sampled numbers (a clearance, a mass): the table, draws and values (3 × 2) and
    the two model arrays made per-sample (one clearance, one mass each): 8 × 8 bytes."""
    scene = load_scene(REPO / "configs" / "clearance-sweep.toml")
    assert memory._per_sample_model_bytes(scene) == 64


@pytest.mark.parametrize("command", ["validate", "run"])
def test_huge_count__one_line_exit_2_nothing_written(tmp_path, monkeypatch, capsys, command):
    path = write_scene(tmp_path, SWEEP.replace("count = 10000", "count = 10000000000"))
    args = [command, path] + (["--out", tmp_path / "runs"] if command == "run" else [])
    ran = in_process(monkeypatch, capsys)(*args, cwd=tmp_path)
    assert_usage_error(ran, "sample.count: 10000000000 samples need about 596 GiB", "available")
    assert not (tmp_path / "runs").exists()


def test_huge_samples_flag__names_the_flag(tmp_path, monkeypatch, capsys):
    path = write_scene(tmp_path, SWEEP)
    ran = in_process(monkeypatch, capsys)(
        "run", path, "--samples", "10000000000", "--out", tmp_path / "runs", cwd=tmp_path
    )
    assert_usage_error(ran, "--samples: 10000000000 samples need about")
    assert not (tmp_path / "runs").exists()


def test_available_memory__is_known_here() -> None:
    available = memory.available_memory()
    assert available is not None and available > 2**20


@pytest.mark.parametrize(
    "config",
    [
        "clearance-sweep",  # equilibrium, modes and shapes
        "fourbar-damper",  # modes along a crank turn
        "slider-crank-flores",  # time histories, a prismatic joint, a contact law
    ],
)
def test_disk_estimate__is_what_the_part_files_hold(tmp_path, config):
    """The estimate's bytes per sample are exactly the part files' data per sample, each
    file's metadata stays within the overhead counted, and the merged (compressed) file
    within its uncompressed bound."""
    import netCDF4

    from mcchain.runner.job import prepare_job
    from mcchain.runner.plan import start_run

    path = REPO / "configs" / f"{config}.toml"
    result = start_run(path, samples=6, chunk_size=4, out=tmp_path, progress=False, keep_parts=True)
    estimate = prepare_job(path, samples=6, chunk_size=4).disk
    assert estimate is not None
    parts = sorted((result.folder / "parts").glob("part-*.nc"))
    assert len(parts) == 2
    for part in parts:
        with netCDF4.Dataset(part) as nc:
            n = nc.dimensions["sample"].size
            data = sum(
                v.size * v.dtype.itemsize for v in nc.variables.values() if "sample" in v.dimensions
            )
        assert data == n * estimate.sample_bytes
        assert data < part.stat().st_size <= data + estimate.file_bytes
    assert sum(p.stat().st_size for p in parts) <= estimate.parts()
    assert (result.folder / "ensemble.nc").stat().st_size <= estimate.merged
