"""netCDF I/O of ensembles: atomic part files and their streaming merge.

A run writes each finished chunk of samples as a *part file* ``part-<start>-<stop>.nc``:
written under a hidden temporary name, fsync'ed, renamed, and the folder fsync'ed, so a
part file is either complete or absent (a process killed mid-write leaves only a
``.part-*.tmp`` that no reader lists). Part files are uncompressed and contiguous: cheap to
write on a thread beside the compute, cheap to read back.

:func:`merge_parts` streams the parts into one ``ensemble.nc``, variable by variable and
sample block by sample block, so memory stays O(block) whatever the ensemble's size. The
merged file is compressed (``zlib``, ``zstd`` or none) and chunked along ``sample`` with
chunk lengths that depend only on the variable's shape, never on how the samples were
computed, so the same data give a byte-identical file whatever the compute chunk size,
thread count or scheduler.
"""

from __future__ import annotations

import logging
import os
import re
import time
from collections import OrderedDict
from collections.abc import Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager, suppress
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from mcchain.ensemble.histories import ROW_DIMS
from mcchain.ensemble.study import SESSION_ATTRIBUTES, attributes_of, same_values, study_attributes
from mcchain.errors import RunError

if TYPE_CHECKING:
    import netCDF4
    import xarray as xr

    from mcchain.ensemble.registry import ChunkVariables

log = logging.getLogger(__name__)

PART_PATTERN = re.compile(r"^part-(\d{12})-(\d{12})\.nc$")
"""Names of finished part files (temporary files never match)."""

CHUNK_TARGET_BYTES = 1 << 20
"""Uncompressed bytes aimed at per HDF5 chunk of the merged file (≈ 1 MiB)."""

WINDOW_SAMPLES = 1 << 13
"""Samples merged per window; every chunk length along ``sample`` is a power of two that
divides it (or the whole, shorter ensemble), so windows never split a chunk."""

WRITE_TARGET_BYTES = 16 << 20
"""Uncompressed bytes copied per read/write call during a merge (bounds its memory)."""

MAX_OPEN_PARTS = 16
"""Part files kept open at once during a merge (≈ 1-2 MB of HDF5 metadata each)."""

COMPRESSIONS = ("zlib", "zstd", "none")


class MergeError(RunError, ValueError):
    """Part files that do not form one ensemble (gap, overlap, mismatched layout)."""


# -- small file-system helpers -------------------------------------------------------------


def fsync_file(path: Path) -> None:
    """Flush a file's data to disk."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def fsync_dir(path: Path) -> None:
    """Flush a directory entry (a rename into it) to disk."""
    fd = os.open(path, os.O_RDONLY | os.O_DIRECTORY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def temporary_name(path: Path) -> Path:
    """The hidden temporary name a file is written under before its rename."""
    return path.with_name(f".{path.name}.{os.getpid()}.tmp")


def commit_file(tmp: Path, path: Path) -> None:
    """Make ``tmp`` durable and visible as ``path`` in one atomic rename."""
    fsync_file(tmp)
    os.replace(tmp, path)
    fsync_dir(path.parent)


def write_text_atomic(path: Path, text: str) -> None:
    """Write a small text file atomically (temporary name, fsync, rename, fsync dir)."""
    path = Path(path)
    tmp = temporary_name(path)
    try:
        tmp.write_text(text, encoding="utf-8")
        commit_file(tmp, path)
    finally:
        with suppress(FileNotFoundError):
            tmp.unlink()


# -- compression ---------------------------------------------------------------------------


def compression_options(compression: str, complevel: int = 1) -> tuple[dict[str, Any], str]:
    """netCDF4 ``createVariable`` keywords for a codec, and a note if it had to change.

    ``zstd`` needs a netCDF-C built with it; without, zlib is used and the note says so.
    """
    import netCDF4

    if compression not in COMPRESSIONS:
        raise ValueError(f"storage.compression: must be one of {COMPRESSIONS}, got {compression!r}")
    note = ""
    if compression == "zstd" and not getattr(netCDF4, "__has_zstandard_support__", False):
        note = "zstd is not supported by this netCDF4/netCDF-C build; using zlib instead"
        compression = "zlib"
    if compression == "none":
        return {}, note
    # netCDF4-python applies the HDF5 shuffle filter with zlib only.
    options = {"compression": compression, "complevel": int(complevel)}
    return options | ({"shuffle": True} if compression == "zlib" else {}), note


def sample_chunk_length(per_sample_bytes: int, nsample: int) -> int:
    """HDF5 chunk length along ``sample``: about :data:`CHUNK_TARGET_BYTES` per chunk.

    A power of two at most :data:`WINDOW_SAMPLES` (or ``nsample`` when that is shorter).
    It depends only on the variable's shape and the sample count, so the merged file's
    layout never depends on the compute chunk size.
    """
    per_sample_bytes = max(int(per_sample_bytes), 1)
    length = max(CHUNK_TARGET_BYTES // per_sample_bytes, 1)
    length = min(1 << (length.bit_length() - 1), WINDOW_SAMPLES)
    return int(min(length, max(nsample, 1)))


# -- writing one Dataset (a part file) -------------------------------------------------------


def _nc_dtype(values: np.ndarray) -> Any:
    if values.dtype.kind in "OUS":
        return str
    if values.dtype.kind == "b":
        return np.dtype(np.int8)
    return values.dtype


def _set_attrs(var: Any, attrs: Mapping[str, Any]) -> None:
    for key, value in attrs.items():
        var.setncattr(key, value)


def _write_chunk(chunk: ChunkVariables, path: Path) -> None:
    import netCDF4

    nc = netCDF4.Dataset(path, "w", format="NETCDF4")
    try:
        nc.set_fill_off()
        nc.set_auto_maskandscale(False)
        for dim, size in chunk.sizes.items():
            nc.createDimension(dim, size)
        for name, (dims, values, var_attrs) in [*chunk.coords.items(), *chunk.data_vars.items()]:
            values = np.asarray(values)
            dtype = _nc_dtype(values)
            contiguous = dtype is not str and 0 not in values.shape
            out = nc.createVariable(name, dtype, dims, contiguous=contiguous)
            attrs = dict(var_attrs)
            if name in chunk.data_vars:
                aux = chunk.auxiliary_coordinates(name)
                if aux:
                    attrs["coordinates"] = " ".join(aux)
            if values.dtype.kind == "b":
                attrs["dtype"] = "bool"
                values = values.astype(np.int8)
            _set_attrs(out, attrs)
            if values.size:
                if dtype is str:
                    out[:] = values.astype(object)
                else:
                    out[:] = values
        _set_attrs(nc, chunk.attrs)
    finally:
        nc.close()


def part_name(start: int, stop: int) -> str:
    """File name of the part holding samples ``start:stop``."""
    return f"part-{start:012d}-{stop:012d}.nc"


@dataclass(frozen=True, order=True)
class Part:
    """A finished part file holding samples ``start:stop``."""

    start: int
    stop: int
    path: Path


def write_part(chunk: ChunkVariables, directory: Path, start: int, stop: int) -> Part:
    """Write one chunk's variables (:func:`~mcchain.ensemble.registry.chunk_variables`)
    atomically as a part file and return it.

    The file becomes visible under its final name only once complete and on disk.
    """
    directory = Path(directory)
    samples = chunk.sizes.get("sample")
    if samples != stop - start:
        raise ValueError(f"part {start}:{stop}: the chunk has {samples} samples")
    path = directory / part_name(start, stop)
    tmp = temporary_name(path)
    try:
        _write_chunk(chunk, tmp)
        commit_file(tmp, path)
    finally:
        with suppress(FileNotFoundError):
            tmp.unlink()
    return Part(start, stop, path)


def list_parts(directory: Path) -> list[Part]:
    """Finished part files of a folder, by start sample (temporaries are ignored)."""
    directory = Path(directory)
    if not directory.is_dir():
        return []
    parts = []
    for entry in os.scandir(directory):
        match = PART_PATTERN.match(entry.name)
        if match:
            parts.append(Part(int(match[1]), int(match[2]), Path(entry.path)))
    return sorted(parts)


def remove_temporaries(directory: Path) -> int:
    """Delete temporaries a killed writer left in ``directory``; returns how many."""
    count = 0
    directory = Path(directory)
    if directory.is_dir():
        for entry in os.scandir(directory):
            if entry.name.startswith(".") and entry.name.endswith(".tmp"):
                with suppress(FileNotFoundError):
                    os.unlink(entry.path)
                    count += 1
    return count


# -- merging ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class MergeStats:
    """What a merge did: uncompressed bytes copied, file size, seconds."""

    nsample: int
    nparts: int
    bytes_in: int
    bytes_out: int
    seconds: float
    note: str = ""

    @property
    def throughput(self) -> float:
        """Uncompressed MB/s."""
        return self.bytes_in / 1e6 / self.seconds if self.seconds > 0 else float("inf")


class _PartCache:
    """Open part files, at most :data:`MAX_OPEN_PARTS` at a time (least recently used
    closed), each checked against the first part when first opened."""

    def __init__(self, parts: Sequence[Part], attrs: Mapping[str, Any] | None = None) -> None:
        self._parts = parts
        self._given = None if attrs is None else dict(attrs)
        self._open: OrderedDict[int, netCDF4.Dataset] = OrderedDict()
        self._checked: set[int] = {0}
        self._layout: dict[str, Any] = {}
        self._fixed: dict[str, np.ndarray] = {}
        self.attrs: dict[str, Any] = {}

    def __call__(self, index: int) -> netCDF4.Dataset:
        import netCDF4

        nc = self._open.pop(index, None)
        if nc is None:
            if len(self._open) >= MAX_OPEN_PARTS:
                _, oldest = self._open.popitem(last=False)
                oldest.close()
            nc = netCDF4.Dataset(self._parts[index].path, "r")
            nc.set_auto_maskandscale(False)
            if index == 0 and not self._layout:
                self._layout = _layout(nc)
                self._fixed = {
                    name: var[:]
                    for name, var in nc.variables.items()
                    if not set(ROW_DIMS) & set(var.dimensions)
                }
                self.attrs = attributes_of(nc) if self._given is None else dict(self._given)
                if self._given is not None:
                    self._check_attrs(nc, self._parts[index].path.name)
            elif index not in self._checked:
                self._check(nc, self._parts[index].path.name)
                self._checked.add(index)
        self._open[index] = nc
        return nc

    def _check(self, nc: netCDF4.Dataset, name_of: str) -> None:
        if _layout(nc) != self._layout:
            raise MergeError(f"{name_of}: variables differ from the first part")
        for name, value in self._fixed.items():
            if not same_values(nc[name][:], value):
                raise MergeError(f"{name_of}: {name} differs from the first part")
        self._check_attrs(nc, name_of)

    def _check_attrs(self, nc: netCDF4.Dataset, name_of: str) -> None:
        # What ran a session's chunks is provenance, not the study: parts written by a
        # session that ran interpreted and by one that ran compiled hold the same values.
        attrs, expected = attributes_of(nc), self.attrs
        attrs = {key: value for key, value in attrs.items() if key not in SESSION_ATTRIBUTES}
        expected = {key: value for key, value in expected.items() if key not in SESSION_ATTRIBUTES}
        if self._given is not None:  # the run grew since the part was written
            attrs, expected = study_attributes(attrs), study_attributes(expected)
        if set(attrs) != set(expected) or not all(
            same_values(value, expected[key]) for key, value in attrs.items()
        ):
            raise MergeError(f"{name_of}: global attributes differ")

    def close(self) -> None:
        for nc in self._open.values():
            nc.close()
        self._open.clear()


def _layout(nc: netCDF4.Dataset) -> dict[str, Any]:
    return {name: (var.dimensions, var.dtype) for name, var in nc.variables.items()}


def check_tiling(parts: Sequence[Part], nsample: int | None = None) -> int:
    """Check that parts cover ``0:nsample`` without gap or overlap; return the count."""
    if not parts:
        raise MergeError("no part files to merge")
    position = 0
    for part in sorted(parts):
        if part.start != position or part.stop <= part.start:
            raise MergeError(f"{part.path.name}: expected a part starting at sample {position}")
        position = part.stop
    if nsample is not None and position != nsample:
        raise MergeError(f"parts cover samples 0:{position}, expected 0:{nsample}")
    return position


def _blocks(n: int, length: int) -> Iterator[tuple[int, int]]:
    for b0 in range(0, n, length):
        yield b0, min(b0 + length, n)


def _read_samples(
    cache: _PartCache,
    starts: np.ndarray,
    stops: np.ndarray,
    name: str,
    b0: int,
    b1: int,
    *,
    descending: bool = False,
) -> np.ndarray:
    """Rows ``b0:b1`` (along the variable's first, row dim) of variable ``name``, gathered
    from the parts that hold them; part ``i`` holds rows ``starts[i]:stops[i]``. The parts
    are opened last first when ``descending`` (the rows come back in order either way)."""
    i = int(np.searchsorted(starts, b0, side="right")) - 1
    while i < len(starts) - 1 and stops[i] <= b0:  # parts without rows of this dim
        i += 1
    spans = []
    while i < len(starts) and starts[i] < b1:
        lo, hi = max(b0, int(starts[i])), min(b1, int(stops[i]))
        if hi > lo:
            spans.append((i, lo - int(starts[i]), hi - int(starts[i])))
        i += 1
    order = reversed(spans) if descending else spans
    pieces = {i: np.asarray(cache(i)[name][lo:hi]) for i, lo, hi in order}
    rows = [pieces[i] for i, _, _ in spans]
    return rows[0] if len(rows) == 1 else np.concatenate(rows)


def _row_offsets(cache: _PartCache, parts: Sequence[Part], dim: str) -> np.ndarray:
    """(nparts + 1,) where each part's rows of ``dim`` start in the merged file: the
    samples' starts, or the running count of the histories a ``"failed"`` run kept."""
    if dim == "sample":
        return np.array([p.start for p in parts] + [parts[-1].stop], dtype=np.int64)
    sizes = [cache(i).dimensions[dim].size for i in range(len(parts))]
    return np.concatenate([[0], np.cumsum(sizes, dtype=np.int64)])


@dataclass
class _Target:
    """A sample-dimension variable of the merged file and how it is copied."""

    name: str
    var: Any
    per_sample: int
    length: int
    step: int
    dim: str = "sample"


def _create_variables(
    dst: netCDF4.Dataset, first: netCDF4.Dataset, options: Mapping[str, Any]
) -> list[_Target]:
    """Create every variable of ``dst`` like the first part's; copy the fixed ones."""
    targets = []
    for name, var in first.variables.items():
        dims = var.dimensions
        if not set(ROW_DIMS) & set(dims):
            copy = dst.createVariable(name, var.dtype, dims)
            _set_attrs(copy, attributes_of(var))
            if var.size:
                copy[:] = var[:]
            continue
        if dims[0] not in ROW_DIMS:
            raise MergeError(f"{name}: {dims[0]} must be the first dim, got {dims}")
        total = dst.dimensions[dims[0]].size
        inner = [dst.dimensions[d].size for d in dims[1:]]
        numeric = var.dtype is not str and np.dtype(var.dtype).kind in "biuf"
        itemsize = np.dtype(var.dtype).itemsize if numeric else 8
        per_sample = itemsize * int(np.prod(inner))
        length = sample_chunk_length(per_sample, total)
        kwargs: dict[str, Any] = dict(options) if numeric else {}
        if itemsize == 1:
            kwargs.pop("shuffle", None)
        chunks = (length, *[max(n, 1) for n in inner])
        target = dst.createVariable(name, var.dtype, dims, chunksizes=chunks, **kwargs)
        _set_attrs(target, attributes_of(var))
        if per_sample == 0 and numeric:
            continue
        step = length * max(WRITE_TARGET_BYTES // max(per_sample * length, 1), 1)
        targets.append(_Target(name, target, per_sample, length, step, dims[0]))
    return targets


@contextmanager
def _no_chunk_cache() -> Iterator[None]:
    """Open and create datasets without an HDF5 chunk cache.

    netCDF's default cache is 64 MiB per variable and stays allocated while the file is
    open, so a merge of many variables would grow by that much per variable. The merge
    reads contiguous parts and writes whole chunks: it needs no cache.
    """
    import netCDF4

    size, nelems, preemption = netCDF4.get_chunk_cache()
    netCDF4.set_chunk_cache(0, nelems, preemption)
    try:
        yield
    finally:
        netCDF4.set_chunk_cache(size, nelems, preemption)


def merge_parts(
    parts: Sequence[Part],
    out: Path,
    *,
    compression: str | None = None,
    complevel: int | None = None,
    nsample: int | None = None,
    attrs: Mapping[str, Any] | None = None,
) -> MergeStats:
    """Stream part files into one compressed netCDF file ``out``, atomically.

    Args:
        parts: finished part files; together they must cover ``0:nsample`` exactly.
        out: the merged file; written under a temporary name and renamed when complete.
        compression: ``zlib``, ``zstd`` (zlib if unsupported, see the note) or ``none``;
            default the ``[storage]`` default (``Storage().compression``).
        complevel: codec level; default ``Storage().complevel``.
        nsample: expected sample count (checked), or ``None``.
        attrs: the merged file's global attributes, for a run that grew (``--extend``,
            ``until``) since some parts were written: a part may then differ from them in
            its sample count only (:func:`study_attributes`). Default: the first part's.

    The layout (dims, variables, attributes) comes from the first part; every other part
    must agree, and variables without a ``sample`` dim (names, ``time``) must be equal in
    all parts. Memory stays O(:data:`WRITE_TARGET_BYTES`).

    Raises:
        MergeError: parts with a gap, an overlap or mismatched layouts.
    """
    import netCDF4

    t0 = time.perf_counter()
    parts = sorted(parts)
    total = check_tiling(parts, nsample)
    if compression is None or complevel is None:
        from mcchain.scene.models import Storage

        default = Storage()
        compression = default.compression if compression is None else compression
        complevel = default.complevel if complevel is None else complevel
    options, note = compression_options(compression, complevel)
    if note:
        log.warning(note)
    out = Path(out)
    tmp = temporary_name(out)
    cache = _PartCache(parts, attrs)
    bytes_in = 0
    try:
        with _no_chunk_cache():
            first = cache(0)
            offsets = {d: _row_offsets(cache, parts, d) for d in ROW_DIMS if d in first.dimensions}
            with netCDF4.Dataset(tmp, "w", format="NETCDF4") as dst:
                dst.set_fill_off()
                dst.set_auto_maskandscale(False)
                for dim, obj in first.dimensions.items():
                    dst.createDimension(dim, int(offsets[dim][-1]) if dim in offsets else obj.size)
                targets = _create_variables(dst, first, options)
                # Row dim by row dim, window by window, variable by variable: the order
                # chunks are written in (hence the file's bytes) depends only on the layout
                # and the row counts (samples; histories kept). Every other variable walks
                # its window backwards: a window spans more parts than the cache keeps
                # open when the compute chunks are small, and a least-recently-used cache
                # swept forwards again and again reopens every part for every variable
                # (then most of a merge is spent opening files), while a sweep back and
                # forth finds all but the turn's far end still open.
                backwards = False
                for dim, rows in offsets.items():
                    along = [t for t in targets if t.dim == dim]
                    window = max(WINDOW_SAMPLES, max((t.length for t in along), default=1))
                    for w0, w1 in _blocks(int(rows[-1]), window):
                        for t in along:
                            blocks = [
                                (b0, min(b0 + t.step, w1))
                                for b0 in range(w0, w1, min(t.step, window))
                            ]
                            for b0, b1 in reversed(blocks) if backwards else blocks:
                                block = _read_samples(
                                    cache, rows[:-1], rows[1:], t.name, b0, b1, descending=backwards
                                )
                                t.var[b0:b1] = block
                                bytes_in += block.nbytes
                            backwards = not backwards
                _set_attrs(dst, cache.attrs)
        cache.close()
        commit_file(tmp, out)
    finally:
        cache.close()
        with suppress(FileNotFoundError):
            tmp.unlink()
    seconds = time.perf_counter() - t0
    return MergeStats(total, len(parts), bytes_in, out.stat().st_size, seconds, note)


# -- reading -----------------------------------------------------------------------------------


def _has_dask() -> bool:
    try:
        import dask.array  # noqa: F401
    except ImportError:
        return False
    return True


class DamagedEnsemble(RunError):
    """An ``ensemble.nc`` that cannot be read (cut short, overwritten): how to rebuild it."""

    def __init__(self, path: Path, reason: BaseException) -> None:
        why = str(reason).strip().splitlines()[0] if str(reason).strip() else type(reason).__name__
        super().__init__(
            f"{path}: cannot be read ({why}): the file is damaged; rebuild it with: "
            f"mcchain run --resume {path.parent} --remerge"
        )


def open_ensemble(path: Path, *, dask: bool = True) -> xr.Dataset:
    """A merged ensemble file as a lazy Dataset (Dask chunks along the file's chunks;
    ``dask=False``: xarray's own lazy arrays, without a task graph per variable, for a
    reader of a few per-sample variables: the verdict a run prints).

    Raises:
        DamagedEnsemble: the file cannot be opened, or its per-sample ``status`` (read here,
            small) cannot be read: a file cut short or overwritten.
    """
    import xarray as xr

    try:
        if dask and _has_dask():
            ds = xr.open_dataset(path, engine="netcdf4", chunks={})
        else:
            ds = xr.open_dataset(path, engine="netcdf4")
        ds["status"].values  # noqa: B018 (a damaged file fails here, not in a plot)
    except (OSError, ValueError, RuntimeError, KeyError) as exc:
        raise DamagedEnsemble(path, exc) from None
    return ds


def open_parts(parts: Iterable[Part]) -> xr.Dataset:
    """Finished part files as one lazy Dataset along ``sample`` (an unfinished run)."""
    import xarray as xr

    paths = [p.path for p in sorted(parts)]
    if not paths:
        raise FileNotFoundError("no finished part files")
    if _has_dask():
        return xr.open_mfdataset(
            paths,
            engine="netcdf4",
            combine="nested",
            concat_dim="sample",
            data_vars="minimal",
            coords="minimal",
            compat="override",
            join="override",
            combine_attrs="override",
            chunks={},
        )
    datasets = [xr.open_dataset(p, engine="netcdf4") for p in paths]
    return xr.concat(
        datasets,
        dim="sample",
        data_vars="minimal",
        coords="minimal",
        compat="override",
        join="override",
        combine_attrs="override",
    )
