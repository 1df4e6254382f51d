"""Run folders: create, resolve, list and open runs; ``run.json``; the lock; the chunks a
run has and lacks.

A run folder ``runs/<timestamp>-<scene>/`` holds:

* ``scene.toml`` — the scene text the run was made from (resume reads it back);
* ``run.json`` — the experiment log: status ``RUNNING``/``COMPLETED``/``FAILED``, start
  and end, argv, versions, git commit, host, threads, wall time per phase, status counts,
  throughput (see :mod:`mcchain.runner.pipeline`);
* ``run.log`` — the log (one line per chunk, warnings, the traceback of a failure);
* ``parts/part-<start>-<stop>.nc`` — finished chunks, each written atomically; deleted once
  merged;
* ``ensemble.nc`` — the merged ensemble, written atomically at the end;
* ``live.rrd`` — with ``--rerun SAMPLES`` and no other sink: the rerun recording of those
  samples, streamed chunk by chunk while the run goes (``live-2.rrd``, ... on a resume);
  it never changes ``ensemble.nc``.

Making a run is the pipeline's job (:mod:`mcchain.runner`); this module only knows the
folder.

This module imports only the standard library at import time (``mcchain runs`` must stay
fast); xarray and netCDF4 are imported when a run is opened or ``run.json`` written.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import fcntl
import itertools
import json
import logging
import os
import re
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from mcchain.errors import RunError
from mcchain.runner import DEFAULT_OUT

if TYPE_CHECKING:
    import xarray as xr

    from mcchain.ensemble.per_sample import StoredEnsemble
    from mcchain.runner.job import Job

log = logging.getLogger("mcchain")

RUNNING, COMPLETED, FAILED = "RUNNING", "COMPLETED", "FAILED"
INTERRUPTED = "INTERRUPTED"
"""Shown by :func:`list_runs` for a RUNNING run whose process is gone (killed)."""

RUN_JSON = "run.json"
SCENE_COPY = "scene.toml"
ENSEMBLE = "ensemble.nc"
LOG_FILE = "run.log"
PARTS = "parts"
LOCK = ".lock"
LIVE_RRD = "live.rrd"


def now() -> str:
    """The local time with its UTC offset, to the second, as ``run.json`` records times."""
    return _dt.datetime.now().astimezone().isoformat(timespec="seconds")


# -- run folders -------------------------------------------------------------------------------


_UNSAFE = re.compile(r"[^A-Za-z0-9._-]+")
_PART_NAME = re.compile(r"^part-\d{12}-\d{12}\.nc$")  # as mcchain.ensemble.io.PART_PATTERN


def _folder_name(stamp: str, scene_name: str, attempt: int) -> str:
    safe = _UNSAFE.sub("-", scene_name).strip("-.") or "scene"
    return f"{stamp}-{safe}" if attempt == 0 else f"{stamp}.{attempt}-{safe}"


def check_new_run_dir(run_dir: str | Path) -> Path:
    """``--run-dir`` must not exist yet; its parent is created later."""
    path = Path(run_dir)
    if path.exists() or path.is_symlink():
        raise RunError(f"--run-dir: {path} already exists (runs are never overwritten)")
    return path


def create_run_folder(out: str | Path, scene_name: str, run_dir: str | Path | None = None) -> Path:
    """Create a fresh run folder atomically (``mkdir``): never an existing one.

    Without ``run_dir``: ``out/<YYYYmmdd-HHMMSS>-<scene>``, and ``<stamp>.<k>-<scene>`` when
    another run took that name in the same second.
    """
    if run_dir is not None:
        path = check_new_run_dir(run_dir)
        path.parent.mkdir(parents=True, exist_ok=True)
        try:
            path.mkdir()
        except FileExistsError:
            raise RunError(f"--run-dir: {path} already exists") from None
        return path
    root = Path(out)
    root.mkdir(parents=True, exist_ok=True)
    stamp = _dt.datetime.now().strftime("%Y%m%d-%H%M%S")
    for attempt in range(10_000):
        path = root / _folder_name(stamp, scene_name, attempt)
        try:
            path.mkdir()
        except FileExistsError:
            continue
        return path
    raise RunError(f"--out: could not create a new run folder in {root}")


def create_run(
    job: Job,
    scene_path: str | Path,
    argv: Sequence[str],
    out: str | Path = DEFAULT_OUT,
    run_dir: str | Path | None = None,
) -> tuple[Path, dict[str, Any]]:
    """A new run of ``job``: its folder (:func:`create_run_folder`) holding the scene's
    text as ``scene.toml``, and its ``run.json`` record before its first session (written
    when the session begins)."""
    from mcchain.runner.provenance import git_state, host_info, software_versions

    folder = create_run_folder(out, job.scene_name, run_dir)
    with open(folder / SCENE_COPY, "w", encoding="utf-8", newline="") as f:
        f.write(job.scene_text)
    record = {
        "id": folder.name,
        "status": RUNNING,
        "scene": job.scene_name,
        "scene_file": str(Path(scene_path).resolve()),
        "samples": job.nsample,
        "seed": job.seed,
        "chunk_size": job.chunk_size,
        "chunks": len(plan_chunks(job.nsample, job.chunk_size)),
        "storage": {
            "history_dtype": job.history_dtype,
            "compression": job.compression,
            "complevel": job.complevel,
        },
        "start": now(),
        "end": None,
        "argv": list(argv),
        "versions": software_versions(),
        "git": git_state(),
        "host": host_info(),
        "pid": os.getpid(),
        "threads": None,
        "scheduler": None,
        "timings": {},
        "wall_time": None,
        "status_counts": None,
        "throughput": {},
        "merge": None,
        "sessions": [],
        "error": None,
        "warnings": list(job.warnings),
        "notes": list(job.notes),
        "kernels": job.kernels,
    }
    return folder, record


def resolve_run(run: str | Path) -> Path:
    """A run folder from a path or an id under ``runs/``."""
    path = Path(run)
    if not path.is_dir() and not path.is_absolute():
        candidate = Path(DEFAULT_OUT) / path
        if candidate.is_dir():
            path = candidate
    if not path.is_dir():
        raise RunError(f"{run}: no such run folder")
    return path


def read_record(folder: Path) -> dict[str, Any]:
    """The ``run.json`` of a run folder."""
    path = Path(folder) / RUN_JSON
    try:
        record: dict[str, Any] = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise RunError(f"{folder}: not a run folder (no {RUN_JSON})") from None
    except (OSError, ValueError) as exc:
        raise RunError(f"{path}: unreadable ({exc})") from None
    return record


def write_record(folder: Path, record: Mapping[str, Any]) -> None:
    """Write ``run.json`` atomically."""
    from mcchain.ensemble.io import write_text_atomic

    write_text_atomic(Path(folder) / RUN_JSON, json.dumps(record, indent=2) + "\n")


@contextlib.contextmanager
def run_lock(folder: Path) -> Iterator[None]:
    """Hold the folder's lock while executing (released by the OS if the process dies)."""
    fd = os.open(Path(folder) / LOCK, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise RunError(f"{folder}: the run is being executed by another process") from None
        yield
    finally:
        os.close(fd)


def close_completed(folder: Path, keep_parts: bool = False) -> None:
    """Remove the part files of a completed run (merged into ``ensemble.nc``; unless
    ``keep_parts``) and its lock file, while :func:`run_lock` still holds it (a completed
    run is never executed again, so no other process waits for it)."""
    parts = Path(folder) / PARTS
    if not keep_parts and parts.is_dir():
        for name in os.listdir(parts):
            if _PART_NAME.match(name):
                (parts / name).unlink()
        with contextlib.suppress(OSError):
            parts.rmdir()
    with contextlib.suppress(FileNotFoundError):
        (Path(folder) / LOCK).unlink()


def is_locked(folder: Path) -> bool:
    """Whether a live process executes the run."""
    return file_locked(Path(folder) / LOCK)


def file_locked(path: Path) -> bool:
    """Whether a live process holds the lock (``flock``) of the file at ``path``."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except FileNotFoundError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    finally:
        os.close(fd)
    return False


class _RunLogHandler(logging.FileHandler):
    """``run.log``'s handler: a line that cannot be written (a full disk) is dropped in
    silence, where logging would print a traceback per line; the run's own error says
    what happened."""

    def handleError(self, record: logging.LogRecord) -> None:
        pass

    def close(self) -> None:
        with contextlib.suppress(OSError):  # the last flush, on a full disk
            super().close()


@contextlib.contextmanager
def run_log(folder: Path) -> Iterator[None]:
    """Copy the ``mcchain`` log (INFO and up) to the folder's ``run.log`` meanwhile (lines
    that cannot be written, on a full disk, are dropped)."""
    handler = _RunLogHandler(Path(folder) / LOG_FILE, encoding="utf-8")
    handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s"))
    handler.setLevel(logging.INFO)
    previous = log.level
    log.addHandler(handler)
    if log.getEffectiveLevel() > logging.INFO:
        log.setLevel(logging.INFO)
    try:
        yield
    finally:
        log.removeHandler(handler)
        log.setLevel(previous)
        handler.close()


# -- the chunks of a run ---------------------------------------------------------------------
# A run's samples 0:nsample are cut into chunks of chunk_size, the cutting starting again at
# every count the run had before it grew (--extend or an until batch: run.json["restarts"]),
# so that the part files written before it grew are still chunks of its plan. The chunking
# never changes the data.


def plan_chunks(
    nsample: int, chunk_size: int, restarts: Sequence[int] = ()
) -> list[tuple[int, int]]:
    """``[(start, stop), ...]`` covering ``0:nsample`` in chunks of ``chunk_size``.

    ``restarts``: sample indices where the chunking starts again (the sizes a run had before
    ``--extend`` or an ``until`` batch added samples), so that the chunks a run computed
    before it grew are still chunks of its plan.
    """
    if nsample < 1:
        raise ValueError(f"nsample: must be >= 1, got {nsample}")
    if chunk_size < 1:
        raise ValueError(f"chunk_size: must be >= 1, got {chunk_size}")
    bounds = sorted({0, nsample, *(b for b in restarts if 0 < b < nsample)})
    return [
        (s, min(s + chunk_size, stop))
        for begin, stop in itertools.pairwise(bounds)
        for s in range(begin, stop, chunk_size)
    ]


def run_chunks(record: Mapping[str, Any], chunk_size: int) -> list[tuple[int, int]]:
    """The chunks of a run: ``run.json["samples"]`` in chunks of ``chunk_size``, the chunking
    starting again at every count the run had before it grew (``run.json["restarts"]``)."""
    return plan_chunks(int(record["samples"]), chunk_size, record.get("restarts", ()))


def extension_base(folder: Path, record: Mapping[str, Any]) -> int:
    """How many samples an unfinished ``--extend`` keeps from ``ensemble.nc`` (0 if none:
    no extension under way, or ``--remerge`` moved the file aside)."""
    extensions = record.get("extensions") or []
    if not extensions or "end" in extensions[-1] or not (Path(folder) / ENSEMBLE).exists():
        return 0
    return int(extensions[-1]["from"])


def missing_chunks(
    folder: Path, record: Mapping[str, Any], chunk_size: int, base: int = 0
) -> list[tuple[int, int]]:
    """The chunks of the run that have no part file yet and do not lie in the first ``base``
    samples (those ``ensemble.nc`` holds before ``--extend`` adds to it); logged.

    Raises:
        RunError: part files that are no chunks of the run (another chunk size).
    """
    from mcchain.ensemble.io import list_parts

    chunks = run_chunks(record, chunk_size)
    todo = {c: c[1] > base for c in chunks}  # chunk -> not held by the extended ensemble.nc
    for part in list_parts(Path(folder) / PARTS):
        if (part.start, part.stop) not in todo:
            raise RunError(
                f"{Path(folder) / PARTS}: part files do not match chunk size {chunk_size}"
            )
        todo[part.start, part.stop] = False
    missing = list(filter(todo.get, todo))  # in order
    log.info(
        "scene %s: %d samples, %d chunks of %d, %d to compute",
        record.get("scene"),
        chunks[-1][1],
        len(chunks),
        chunk_size,
        len(missing),
    )
    return missing


def missing_samples(folder: Path, record: Mapping[str, Any]) -> int:
    """Samples of a run (``run.json["samples"]``) that neither a finished part file nor,
    during an ``--extend``, the ``ensemble.nc`` it extends holds."""
    from mcchain.ensemble.io import list_parts

    held = sum(p.stop - p.start for p in list_parts(Path(folder) / PARTS))
    return int(record["samples"]) - extension_base(folder, record) - held


# -- reading -----------------------------------------------------------------------------------


def open_run(run: str | Path) -> xr.Dataset:
    """The ensemble of a run as a lazy :class:`xarray.Dataset`.

    A completed run opens ``ensemble.nc``; an unfinished one opens its finished part files
    (never a temporary), i.e. the samples computed so far.
    """
    from mcchain.ensemble.io import list_parts, open_ensemble, open_parts

    folder = resolve_run(run)
    if (folder / ENSEMBLE).exists():
        return open_ensemble(folder / ENSEMBLE)
    parts = list_parts(folder / PARTS)
    if not parts:
        raise RunError(f"{run}: no {ENSEMBLE} and no finished chunks yet")
    return open_parts(parts)


def open_stored_run(run: str | Path) -> StoredEnsemble:
    """The ensemble of a run for the decision readers (``verdict``, ``export --requirements``,
    ``confirm``): a completed run's ``ensemble.nc`` read with netCDF4 alone
    (:func:`mcchain.ensemble.per_sample.open_stored`: xarray only where a variable needs
    decoding), an unfinished run's finished parts as :func:`open_run` gives them. Either
    closes as a context manager."""
    from mcchain.ensemble.per_sample import open_stored

    folder = resolve_run(run)
    if (folder / ENSEMBLE).is_file():
        return open_stored(folder / ENSEMBLE)
    return open_run(folder)


@dataclass(frozen=True)
class RunInfo:
    """One line of ``mcchain runs``."""

    id: str
    path: Path
    scene: str
    samples: int | None
    status_counts: dict[str, int]
    wall_time: float | None
    state: str
    start: str
    chunks_done: int | None = None
    chunks: int | None = None


def list_runs(out: str | Path = DEFAULT_OUT) -> list[RunInfo]:
    """Runs under ``out`` (folders with a ``run.json``), oldest first."""
    root = Path(out)
    if not root.is_dir():
        return []
    runs = []
    for entry in sorted(root.iterdir()):
        if not (entry / RUN_JSON).is_file():
            continue
        try:
            r = read_record(entry)
        except RunError:
            continue
        state = str(r.get("status", "?"))
        if state == RUNNING and not is_locked(entry):
            state = INTERRUPTED
        done = None
        if state != COMPLETED and (entry / PARTS).is_dir():
            done = sum(1 for name in os.listdir(entry / PARTS) if _PART_NAME.match(name))
        runs.append(
            RunInfo(
                id=entry.name,
                path=entry,
                scene=str(r.get("scene", "?")),
                samples=r.get("samples"),
                status_counts=dict(r.get("status_counts") or {}),
                wall_time=r.get("wall_time"),
                state=state,
                start=str(r.get("start", "")),
                chunks_done=done,
                chunks=r.get("chunks"),
            )
        )
    return sorted(runs, key=lambda info: (info.start, info.id))


def format_runs(runs: Sequence[RunInfo]) -> str:
    """``mcchain runs`` table: id, scene, samples, status counts, wall time, state."""
    header = ("id", "scene", "samples", "status", "wall", "state")
    rows = [header]
    for info in runs:
        counts = info.status_counts
        flags = " ".join(
            f"{k}={v}" for k, v in counts.items() if k not in ("samples",) and (v or k == "ok")
        )
        if info.chunks_done is not None:
            flags = f"chunks {info.chunks_done}/{info.chunks}"
        wall = "-" if info.wall_time is None else f"{info.wall_time:.1f}s"
        samples = "-" if info.samples is None else str(info.samples)
        rows.append((info.id, info.scene, samples, flags or "-", wall, info.state))
    widths = [max(len(row[i]) for row in rows) for i in range(len(header))]
    return "\n".join(
        "  ".join(cell.ljust(w) for cell, w in zip(row, widths, strict=True)).rstrip()
        for row in rows
    )


def writable_folder(path: Path, flag: str) -> None:
    """Create ``path`` (and its parents) unless it exists, and check that files can be made
    in it; else raise ``RunError`` naming ``flag``, the folder and the reason."""
    try:
        path.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise RunError(f"{flag}: {path} is a file, not a folder") from None
    except OSError as exc:
        raise RunError(f"{flag}: cannot create the folder {path} ({exc.strerror})") from None
    if not os.access(path, os.W_OK | os.X_OK):
        raise RunError(f"{flag}: cannot write into {path} (permission denied)")
