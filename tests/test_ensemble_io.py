"""Part files (atomic) and their streaming merge into ensemble.nc."""

from __future__ import annotations

import filecmp
import itertools
import sys
from pathlib import Path

import netCDF4
import pytest
import xarray as xr
from test_runs_support import FakeScene, FakeSection, FakeSimulate, FakeStorage, fake_model
from test_runs_support import fake_solve as solve

from mcchain.ensemble import io
from mcchain.ensemble.io import MergeError, list_parts, merge_parts, open_parts, write_part
from mcchain.ensemble.registry import (
    ChunkVariables,
    build_dataset,
    chunk_variables,
    validate_dataset,
)

NSAMPLE = 50
ATTRS = {"scene": "[scene]\nname = 'x'\n", "seed": 3, "settings": "{}"}


def scene(steps: int = 7) -> FakeScene:
    return FakeScene(
        text="",
        scene=FakeSection(),
        sample=FakeSection(),
        storage=FakeStorage(),
        fake=FakeSection(),
        simulate=FakeSimulate(1e-3 * steps, 1e-4, steps),
    )


def write_parts(directory: Path, bounds: list[int], steps: int = 7) -> list[io.Part]:
    directory.mkdir(parents=True, exist_ok=True)
    model = fake_model(bounds[-1])
    parts = []
    for a, b in itertools.pairwise(bounds):
        chunk = model.select(a, b)
        variables = chunk_variables(solve(chunk, scene(steps)), chunk, start=a, attrs=ATTRS)
        parts.append(write_part(variables, directory, a, b))
    return parts


def whole(n: int = NSAMPLE) -> xr.Dataset:
    model = fake_model(n)
    return build_dataset(solve(model, scene()), model, attrs=ATTRS)


def test_write_part__round_trips_and_leaves_no_temporary(tmp_path: Path) -> None:
    (part,) = write_parts(tmp_path, [0, 20])
    assert part.path.name == "part-000000000000-000000000020.nc"
    assert sorted(p.name for p in tmp_path.iterdir()) == [part.path.name]
    with xr.open_dataset(part.path) as ds:
        validate_dataset(ds, "float32")
        xr.testing.assert_identical(ds.load(), whole(20))


def test_write_part__failure_mid_write_leaves_nothing_visible(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    real = io._write_chunk

    def broken(chunk: ChunkVariables, path: Path) -> None:
        real(chunk, path)
        with open(path, "r+b") as f:  # a half-written file...
            f.truncate(100)
        raise OSError("disk full")  # ...then the writer dies

    monkeypatch.setattr(io, "_write_chunk", broken)
    with pytest.raises(OSError, match="disk full"):
        write_parts(tmp_path, [0, 10])
    assert list(tmp_path.iterdir()) == []


def test_write_and_merge__without_xarray(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A run writes and merges its parts without xarray (with pandas and dask, its import
    took 0.4-0.6 s of every run); the merged file reads back as the whole Dataset."""
    for name in ("xarray", "pandas", "dask"):
        monkeypatch.setitem(sys.modules, name, None)  # `import xarray` now fails
    merge_parts(write_parts(tmp_path / "parts", [0, 10, 25]), tmp_path / "e.nc")
    monkeypatch.undo()
    with xr.open_dataset(tmp_path / "e.nc") as ds:
        xr.testing.assert_identical(ds.load(), whole(25))


def test_list_parts__ignores_temporaries_and_other_files(tmp_path: Path) -> None:
    parts = write_parts(tmp_path, [0, 10, 25])
    (tmp_path / ".part-000000000025-000000000050.nc.123.tmp").write_bytes(b"\x89HDF partial")
    (tmp_path / "part-25-50.nc").write_bytes(b"junk")
    (tmp_path / "notes.txt").write_text("x")
    assert list_parts(tmp_path) == parts
    assert io.remove_temporaries(tmp_path) == 1
    assert list_parts(tmp_path / "missing") == []


def test_merge__equals_the_ensemble_built_at_once(tmp_path: Path) -> None:
    parts = write_parts(tmp_path / "parts", [0, 16, 32, 48, 50])
    stats = merge_parts(parts, tmp_path / "ensemble.nc", nsample=NSAMPLE)
    assert stats.nsample == NSAMPLE and stats.nparts == 4 and stats.bytes_in > 0
    with xr.open_dataset(tmp_path / "ensemble.nc") as ds:
        validate_dataset(ds, "float32")
        xr.testing.assert_identical(ds.load(), whole())
    assert not any(p.name.endswith(".tmp") for p in tmp_path.iterdir())


def test_merge__file_is_byte_identical_whatever_the_part_tiling(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # Small HDF5 chunks and copy blocks so blocks straddle part boundaries.
    monkeypatch.setattr(io, "CHUNK_TARGET_BYTES", 600)
    monkeypatch.setattr(io, "WRITE_TARGET_BYTES", 2000)
    tilings = [[0, 50], [0, 1, 2, 30, 50], [0, 7, 14, 21, 28, 35, 42, 49, 50]]
    for k, bounds in enumerate(tilings):
        merge_parts(write_parts(tmp_path / f"p{k}", bounds), tmp_path / f"e{k}.nc")
    assert filecmp.cmp(tmp_path / "e0.nc", tmp_path / "e1.nc", shallow=False)
    assert filecmp.cmp(tmp_path / "e0.nc", tmp_path / "e2.nc", shallow=False)
    with xr.open_dataset(tmp_path / "e2.nc") as ds:
        xr.testing.assert_identical(ds.load(), whole())


@pytest.mark.parametrize(
    ("bounds", "message"),
    [([0, 10, 20], "parts cover samples 0:20, expected 0:50"), ([5, 50], "starting at sample 0")],
)
def test_merge__rejects_gaps(tmp_path: Path, bounds: list[int], message: str) -> None:
    model_bounds = [0, *bounds] if bounds[0] else bounds
    parts = write_parts(tmp_path / "parts", model_bounds)
    parts = [p for p in parts if p.start >= bounds[0]]
    with pytest.raises(MergeError, match=message):
        merge_parts(parts, tmp_path / "e.nc", nsample=NSAMPLE)
    assert not (tmp_path / "e.nc").exists()


def test_merge__rejects_overlap_and_mismatched_parts(tmp_path: Path) -> None:
    a = write_parts(tmp_path / "a", [0, 10, 20])
    b = write_parts(tmp_path / "b", [0, 15])
    with pytest.raises(MergeError, match="starting at sample 10"):
        merge_parts([*a, b[0]], tmp_path / "e.nc")
    c = write_parts(tmp_path / "c", [0, 10, 20], steps=4)  # other time axis
    with pytest.raises(MergeError, match="differ"):
        merge_parts([a[0], c[1]], tmp_path / "e.nc")
    assert not (tmp_path / "e.nc").exists()


@pytest.mark.parametrize("compression", ["zlib", "zstd", "none"])
def test_merge__compression_and_chunking_along_samples(
    tmp_path: Path, compression: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(io, "CHUNK_TARGET_BYTES", 4096)
    merge_parts(
        write_parts(tmp_path / "p", [0, 25, 50]),
        tmp_path / "e.nc",
        compression=compression,
        complevel=3,
    )
    with netCDF4.Dataset(tmp_path / "e.nc") as nc:
        q = nc["q"]
        per_sample = 7 * 2 * 3 * 4
        assert q.chunking() == [16, 7, 2, 3]  # power of two <= 4096 / per_sample
        assert 16 * per_sample <= 4096 < 32 * per_sample
        filters = q.filters()
        if compression == "none":
            assert not filters["zlib"] and not filters["zstd"]
        else:
            assert filters[compression] and filters["complevel"] == 3
            assert filters["shuffle"] == (compression == "zlib")
        assert nc["status"].chunking() == [NSAMPLE]
        assert nc["body"].dtype is str
    with xr.open_dataset(tmp_path / "e.nc") as ds:
        xr.testing.assert_identical(ds.load(), whole())


def test_compression_options__zstd_falls_back_to_zlib_with_a_note(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    options, note = io.compression_options("zstd", 2)
    assert options["compression"] == "zstd" and note == ""
    monkeypatch.setattr(netCDF4, "__has_zstandard_support__", False)
    options, note = io.compression_options("zstd", 2)
    assert options == {"compression": "zlib", "complevel": 2, "shuffle": True}
    assert "zstd is not supported" in note
    with pytest.raises(ValueError, match=r"storage\.compression"):
        io.compression_options("lz4")


def test_merge__bounded_blocks(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Every read of the merge is at most one write block, never the whole ensemble."""
    monkeypatch.setattr(io, "CHUNK_TARGET_BYTES", 1000)
    monkeypatch.setattr(io, "WRITE_TARGET_BYTES", 3000)
    largest = 0
    real = io._read_samples

    def spy(*args, **kwargs):  # type: ignore[no-untyped-def]
        nonlocal largest
        block = real(*args, **kwargs)
        largest = max(largest, block.nbytes)
        return block

    monkeypatch.setattr(io, "_read_samples", spy)
    merge_parts(write_parts(tmp_path / "p", [0, 16, 32, 50]), tmp_path / "e.nc")
    q_bytes = whole().q.nbytes
    assert 0 < largest <= 3000 + 1000 < q_bytes


def test_merge__a_window_wider_than_the_open_parts_opens_each_part_about_once(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Ten parts in one window, three kept open: a forward sweep per variable reopened all
    ten for every variable (a 500-sample chunk of a 10^5-sample run: 3,615 opens, most of a
    112 s merge); back and forth, the turns find the last parts still open. The merged
    values and bytes do not depend on the parts."""
    monkeypatch.setattr(io, "MAX_OPEN_PARTS", 3)
    bounds = [0, 5, 10, 15, 20, 25, 30, 35, 40, 45, 50]
    parts = write_parts(tmp_path / "p", bounds)
    opens = 0
    real = netCDF4.Dataset

    def counted(path, mode="r", *args, **kwargs):  # type: ignore[no-untyped-def]
        nonlocal opens
        opens += mode == "r"
        return real(path, mode, *args, **kwargs)

    monkeypatch.setattr(netCDF4, "Dataset", counted)
    merge_parts(parts, tmp_path / "e.nc")
    monkeypatch.undo()
    with netCDF4.Dataset(tmp_path / "e.nc") as nc:
        sweeps = sum("sample" in var.dimensions for var in nc.variables.values())
    assert sweeps > 5
    # A forward sweep: 10 opens a variable; back and forth: 10, then 7 a variable.
    assert opens <= 10 + (sweeps - 1) * (10 - 3 + 1) < 10 * sweeps
    with xr.open_dataset(tmp_path / "e.nc") as ds:
        xr.testing.assert_identical(ds.load(), whole())
    merge_parts(write_parts(tmp_path / "q", [0, 7, 50]), tmp_path / "f.nc")
    assert filecmp.cmp(tmp_path / "e.nc", tmp_path / "f.nc", shallow=False)


def test_open_parts__lazy_union_of_finished_parts(tmp_path: Path) -> None:
    parts = write_parts(tmp_path, [0, 16, 32, 50])
    ds = open_parts(parts[:2])
    assert ds.q.chunks is not None  # lazy (dask)
    expected = whole().isel(sample=slice(0, 32))
    xr.testing.assert_identical(ds.load(), expected)
