"""Run folders: create, execute, resume, list and open runs (DESIGN §6).

A run folder ``runs/<timestamp>-<scene>/`` holds:

* ``scene.toml`` — the scene text the run was made from (resume reads it back);
* ``run.json`` — the experiment log: status ``RUNNING``/``COMPLETED``/``FAILED``, start
  and end, argv, versions, git commit, host, threads, wall time per phase, status counts,
  throughput (see :func:`execute`);
* ``run.log`` — the log (one line per chunk, warnings, the traceback of a failure);
* ``parts/part-<start>-<stop>.nc`` — finished chunks, each written atomically; deleted once
  merged;
* ``ensemble.nc`` — the merged ensemble, written atomically at the end;
* ``live.rrd`` — with ``--rerun SAMPLES`` and no other sink: the rerun recording of those
  samples, streamed chunk by chunk while the run goes (``live-2.rrd``, ... on a resume);
  it never changes ``ensemble.nc``.

Nothing here depends on timing: ``ensemble.nc`` holds no timestamps or host names, so the
same scene and seed give a byte-identical file whatever the chunk size, thread count or
scheduler, and a resumed run equals an uninterrupted one.

This module imports only the standard library at import time (``mcchain runs`` must stay
fast); numpy, xarray, netCDF4, numba and the solvers are imported when a run executes.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import fcntl
import importlib.metadata
import json
import logging
import os
import platform
import re
import socket
import subprocess
import sys
import time
import traceback
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from mcchain import __version__
from mcchain.errors import RunError

if TYPE_CHECKING:
    import xarray as xr

    from mcchain.ensemble.io import MergeStats
    from mcchain.model import Model
    from mcchain.parallel import ExecutionStats, SolveFn

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

DEFAULT_OUT = "runs"

DEPENDENCIES = ("numpy", "numba", "scipy", "xarray", "netCDF4", "pydantic")
"""Packages whose versions are recorded in ``ensemble.nc`` and ``run.json``."""

Loader = Callable[[Path, "int | None", "int | None"], tuple[Any, "Model"]]
"""``loader(scene_path, samples, seed) -> (scene, model)``; raises ``SceneError``."""


# -- live streaming options --------------------------------------------------------------------


@dataclass(frozen=True)
class LiveOptions:
    """``mcchain run --rerun SAMPLES [--rerun-save FILE.rrd | --rerun-spawn]``.

    Attributes:
        samples: global sample indices to stream (distinct, >= 0).
        save: write the recording to this file (overwritten if it exists).
        spawn: spawn a rerun viewer instead.
        With neither sink: ``<run folder>/live.rrd`` (:data:`LIVE_RRD`; on a resume the first
        free of ``live-2.rrd``, ``live-3.rrd``, ..., so an earlier session's file stays).
    """

    samples: tuple[int, ...]
    save: Path | None = None
    spawn: bool = False

    def __post_init__(self) -> None:
        if not self.samples:
            raise RunError("--rerun: no sample index given")
        if any(not isinstance(s, int) or s < 0 for s in self.samples):
            raise RunError(f"--rerun: sample indices are integers >= 0, got {list(self.samples)}")
        if self.save is not None and self.spawn:
            raise RunError("--rerun-spawn: cannot be combined with --rerun-save (one sink)")
        if self.save is not None and Path(self.save).is_dir():
            raise RunError(f"--rerun-save: {self.save} is a directory")


def parse_rerun_samples(text: str) -> tuple[int, ...]:
    """``"0,3"`` -> ``(0, 3)`` (duplicates dropped); raises :class:`RunError` naming ``--rerun``."""
    parts = [part.strip() for part in text.split(",")]
    try:
        values = [int(part) for part in parts if part]
    except ValueError:
        raise RunError(
            f"--rerun: expected comma-separated sample indices like 0,3, got {text!r}"
        ) from None
    if not values:
        raise RunError(f"--rerun: expected comma-separated sample indices like 0,3, got {text!r}")
    if any(v < 0 for v in values):
        raise RunError(f"--rerun: sample indices are >= 0, got {text!r}")
    return tuple(dict.fromkeys(values))


def check_live(live: LiveOptions | None, nsample: int) -> None:
    """Every ``--rerun`` index is a sample of the run (checked before anything is written)."""
    if live is None:
        return
    outside = [s for s in live.samples if s >= nsample]
    if outside:
        raise RunError(
            f"--rerun: sample {outside[0]} is not in the run "
            f"({nsample} sample{'s' if nsample != 1 else ''}: 0..{nsample - 1})"
        )


# -- environment -------------------------------------------------------------------------------


def software_versions() -> dict[str, str]:
    """mcchain, Python, the dependencies, and the netCDF-C/HDF5 libraries."""
    versions = {"mcchain": __version__, "python": platform.python_version()}
    for name in DEPENDENCIES:
        with contextlib.suppress(importlib.metadata.PackageNotFoundError):
            versions[name] = importlib.metadata.version(name)
    try:
        import netCDF4

        versions["netcdf-c"] = str(netCDF4.__netcdf4libversion__)
        versions["hdf5"] = str(netCDF4.__hdf5libversion__)
    except ImportError:  # pragma: no cover - netCDF4 is a dependency
        pass
    return versions


def git_state(path: Path | None = None) -> dict[str, Any]:
    """Commit and dirty flag of the git checkout holding mcchain (``None`` outside git)."""
    path = path or Path(__file__).resolve().parent
    try:
        commit = subprocess.run(
            ["git", "rev-parse", "HEAD"],
            cwd=path,
            capture_output=True,
            text=True,
            timeout=10,
            check=True,
        ).stdout.strip()
        changes = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"],
            cwd=path,
            capture_output=True,
            text=True,
            timeout=10,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return {"commit": None, "dirty": None}
    return {"commit": commit, "dirty": bool(changes)}


def host_info() -> dict[str, Any]:
    """Host name, CPU model and count, platform."""
    cpu = platform.processor() or ""
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    return {
        "name": socket.gethostname(),
        "cpu": cpu,
        "cpu_count": os.cpu_count(),
        "platform": platform.platform(),
    }


def _now() -> str:
    return _dt.datetime.now().astimezone().isoformat(timespec="seconds")


# -- the job: scene + model + settings -----------------------------------------------------------


@dataclass
class Job:
    """Everything a run computes from, independent of how it is executed.

    Attributes:
        scene: the validated scene (``mcchain.scene.Scene``).
        model: the compiled model of all samples.
        scene_text: the scene file's text (copied to ``scene.toml``, stored in attributes).
        scene_name: ``[scene] name``.
        nsample: number of samples.
        seed: sampling seed (``None`` without ``[sample]``).
        chunk_size: samples per chunk (execution only: never changes the data).
        history_dtype, compression, complevel: ``[storage]`` settings.
        steps_per_sample: integration steps per sample (``None`` without ``[simulate]``).
        settings: resolved settings stored in ``ensemble.nc`` (no execution details).
    """

    scene: Any
    model: Model
    scene_text: str
    scene_name: str
    nsample: int
    seed: int | None
    chunk_size: int
    history_dtype: str
    compression: str
    complevel: int
    steps_per_sample: int | None = None
    settings: dict[str, Any] = field(default_factory=dict)

    def attributes(self, versions: Mapping[str, str]) -> dict[str, Any]:
        """Global attributes of ``ensemble.nc`` (and of every part file)."""
        return {
            "Conventions": "CF-1.10",
            "title": f"mcchain ensemble of scene {self.scene_name}",
            "source": f"mcchain {__version__}",
            "scene_name": self.scene_name,
            "scene": self.scene_text,
            "settings": json.dumps(self.settings, sort_keys=True),
            "seed": "none" if self.seed is None else int(self.seed),
            "sample_count": int(self.nsample),
            "mcchain_version": __version__,
            "versions": json.dumps(dict(versions), sort_keys=True),
        }


def default_loader(path: Path, samples: int | None, seed: int | None) -> tuple[Any, Model]:
    """Load, compile and check a scene with the real scene module and statics checks."""
    from mcchain.scene import compile_model, load_scene
    from mcchain.solvers.statics import check_scene

    scene = load_scene(path)
    model = compile_model(scene, nsample=samples, seed=seed)
    check_scene(model)
    return scene, model


def _section(scene: Any, name: str) -> Any:
    return getattr(scene, name, None)


def _dump(obj: Any) -> Any:
    if hasattr(obj, "model_dump"):
        return obj.model_dump(mode="json")
    return obj


def resolved_settings(scene: Any, nsample: int, seed: int | None) -> dict[str, Any]:
    """The scene with every default filled in, the sample count and the seed.

    Execution details (chunk size, threads, scheduler) are left out on purpose: they never
    change the data and must not change the file.
    """
    data = _dump(scene)
    data = dict(data) if isinstance(data, Mapping) else {}
    data.pop("text", None)
    storage = data.get("storage")
    if isinstance(storage, Mapping):
        data["storage"] = {k: v for k, v in storage.items() if k != "chunk_size"}
    return {"scene": data, "samples": int(nsample), "seed": seed}


def _steps_per_sample(scene: Any) -> int | None:
    sim = _section(scene, "simulate")
    t_end, dt = getattr(sim, "t_end", None), getattr(sim, "dt", None)
    if not t_end or not dt:
        return None
    return round(float(t_end) / float(dt))


def _check_positive(name: str, value: int | None) -> None:
    if value is not None and (not isinstance(value, int) or value < 1):
        raise RunError(f"{name}: must be an integer >= 1, got {value!r}")


def prepare_job(
    scene_path: str | Path,
    *,
    samples: int | None = None,
    seed: int | None = None,
    chunk_size: int | None = None,
    loader: Loader | None = None,
) -> Job:
    """Load, compile and check a scene; nothing is written.

    Raises:
        SceneError: a bad scene (one line naming the key).
        RunError: a bad argument.
    """
    _check_positive("--samples", samples)
    _check_positive("--chunk-size", chunk_size)
    if seed is not None and (not isinstance(seed, int) or seed < 0):
        raise RunError(f"--seed: must be an integer >= 0, got {seed!r}")
    path = Path(scene_path)
    scene, model = (loader or default_loader)(path, samples, seed)
    from mcchain.scene.models import Storage

    # A scene without ``[storage]`` (a fake) gets the schema's defaults.
    storage = _section(scene, "storage") or Storage()
    chunk = chunk_size or storage.chunk_size
    _check_positive("storage.chunk_size", chunk)
    effective_seed: Any = model.meta.get("seed", seed)
    if effective_seed is None:
        effective_seed = getattr(_section(scene, "sample"), "seed", None)
    effective_seed = None if effective_seed is None else int(effective_seed)
    text = getattr(scene, "text", None)
    if text is None:
        text = path.read_text(encoding="utf-8")
    name = getattr(_section(scene, "scene"), "name", None) or path.stem
    nsample = int(model.nsample)
    return Job(
        scene=scene,
        model=model,
        scene_text=text,
        scene_name=str(name),
        nsample=nsample,
        seed=effective_seed,
        chunk_size=int(chunk),
        history_dtype=str(storage.history_dtype),
        compression=str(storage.compression),
        complevel=int(storage.complevel),
        steps_per_sample=_steps_per_sample(scene),
        settings=resolved_settings(scene, nsample, effective_seed),
    )


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


def is_locked(folder: Path) -> bool:
    """Whether a live process executes the run."""
    try:
        fd = os.open(Path(folder) / LOCK, os.O_RDONLY)
    except FileNotFoundError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    finally:
        os.close(fd)
    return False


@contextlib.contextmanager
def _run_log(folder: Path) -> Iterator[None]:
    handler = logging.FileHandler(Path(folder) / LOG_FILE, encoding="utf-8")
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


# -- execution ---------------------------------------------------------------------------------


@dataclass
class RunResult:
    """What :func:`start_run` / :func:`resume_run` return."""

    folder: Path
    record: dict[str, Any]

    def summary(self) -> list[str]:
        """Human lines for the CLI (the folder is printed after them)."""
        r = self.record
        counts = r.get("status_counts") or {}
        flags = ", ".join(f"{k} {v}" for k, v in counts.items() if v and k != "samples")
        t = r.get("timings", {})
        tp = r.get("throughput", {})
        lines = [
            f"{r['scene']}: {r['samples']} samples in {r['chunks']} chunks "
            f"({r['sessions'][-1]['chunks_computed']} computed now); {flags or 'no samples'}",
            f"wall {t.get('total', 0):.2f} s (kernels {t.get('kernel', 0):.2f} s, "
            f"merge {t.get('merge', 0):.2f} s); {tp.get('samples_per_s') or 0:,.0f} samples/s",
        ]
        if tp.get("instance_steps_per_s"):
            lines.append(f"{tp['instance_steps_per_s']:.3g} instance-steps/s")
        live = r["sessions"][-1].get("rerun") if r.get("sessions") else None
        if live:
            lines.append(_live_summary(live))
        return lines


def _live_summary(live: Mapping[str, Any]) -> str:
    streamed = ", ".join(map(str, live.get("streamed") or [])) or "none"
    line = f"rerun: samples {streamed} streamed to {live.get('sink')}"
    if live.get("computed_before"):
        before = ", ".join(map(str, live["computed_before"]))
        line += f"; {before} computed before this session (replay with mcchain show)"
    if live.get("error"):
        line += f"; stream stopped: {live['error']}"
    return line


class _LiveRun:
    """The rerun stream of one session (``--rerun``).

    :meth:`open` creates the sink before the first chunk (a spawned viewer shows up at once);
    :meth:`observe` is handed each solved chunk on the thread where the results arrive (the
    main thread: rerun recording and the chunk loop share it, never a numba thread or a Dask
    worker), builds the chunk's Dataset with the registry as the part writer does, and logs
    the chunk's selected samples with :class:`mcchain.viz.playback.LiveStream`; :meth:`close`
    completes the file, also after a failure or Ctrl-C. The stream only reads the outputs: it
    never changes ``ensemble.nc``. A stream that fails (no viewer, a full disk) is a warning
    in ``run.log`` and ``run.json`` and the run goes on without it. rerun is imported here
    only, when ``--rerun`` is used.

    ``info`` (the session's ``run.json["sessions"][-1]["rerun"]``) is kept up to date:
    samples, sink, streamed, computed_before, seconds, error.
    """

    def __init__(self, options: LiveOptions, job: Job, folder: Path, info: dict[str, Any]):
        self.options = options
        self.job = job
        self.folder = folder
        self.info = info
        self.stream: Any = None
        info.update(
            samples=list(options.samples),
            sink=None,
            streamed=[],
            computed_before=[],
            seconds=0.0,
            error=None,
        )

    def _default_path(self) -> Path:
        path = self.folder / LIVE_RRD
        k = 2
        while path.exists():
            path = self.folder / f"{Path(LIVE_RRD).stem}-{k}.rrd"
            k += 1
        return path

    def open(self, chunks: Sequence[tuple[int, int]]) -> None:
        """Open the sink for the selected samples in ``chunks`` (those this session computes)."""
        todo = [s for s in self.options.samples if any(a <= s < b for a, b in chunks)]
        before = [s for s in self.options.samples if s not in todo]
        self.info["computed_before"] = before
        if before:
            log.warning(
                "--rerun: samples %s were computed before this session (replay them with "
                "mcchain show)",
                ", ".join(map(str, before)),
            )
        if not todo:
            self.info["sink"] = "nothing (no selected sample left to compute)"
            return
        if self.options.spawn:
            save, sink = None, "a spawned viewer"
        else:
            save = Path(self.options.save) if self.options.save else self._default_path()
            sink = str(save)
        self.info["sink"] = sink
        t0 = time.perf_counter()
        try:
            from mcchain.viz.playback import LiveStream

            if save is not None:
                save.parent.mkdir(parents=True, exist_ok=True)
            self.stream = LiveStream(todo, save=save, spawn=self.options.spawn)
            log.info("--rerun: streaming samples %s to %s", ", ".join(map(str, todo)), sink)
        except Exception as exc:
            self._fail(exc)
        self.info["seconds"] += time.perf_counter() - t0

    def observe(self, outputs: dict[str, Any], start: int, stop: int) -> None:
        """Log the selected samples of the solved chunk ``start:stop`` (if it holds any)."""
        stream = self.stream
        if stream is None or not any(start <= s < stop for s in stream.samples):
            return
        from mcchain.ensemble.registry import build_dataset

        t0 = time.perf_counter()
        try:
            chunk = self.job.model.select(start, stop)
            ds = build_dataset(outputs, chunk, start=start, history_dtype=self.job.history_dtype)
            logged = stream.log_chunk(ds, chunk, start)
            self.info["streamed"] = self.info["streamed"] + [int(s) for s in logged]
        except Exception as exc:
            self._fail(exc)
        self.info["seconds"] += time.perf_counter() - t0

    def close(self) -> None:
        """Flush and close the sink (a saved file is then complete)."""
        stream, self.stream = self.stream, None
        if stream is None:
            return
        t0 = time.perf_counter()
        try:
            stream.close()
        except Exception as exc:
            self._fail(exc)
        self.info["seconds"] += time.perf_counter() - t0

    def _fail(self, exc: Exception) -> None:
        message = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        self.info["error"] = message
        log.warning("--rerun: the live stream stopped (the run goes on): %s", message, exc_info=exc)
        stream, self.stream = self.stream, None
        if stream is not None:
            with contextlib.suppress(Exception):
                stream.close()


def _status_counts(path: Path) -> dict[str, int]:
    """Status counts of a merged ensemble, read block by block."""
    import netCDF4
    import numpy as np

    from mcchain.status import counts

    total: dict[str, int] = {}
    with netCDF4.Dataset(path) as nc:
        var = nc["status"]
        n = var.shape[0]
        for b0 in range(0, n, 1 << 20):
            block = np.asarray(var[b0 : min(b0 + (1 << 20), n)])
            for key, value in counts(block).items():
                total[key] = total.get(key, 0) + value
        total["samples"] = int(n)
    return total


def _new_record(job: Job, folder: Path, argv: Sequence[str], scene_path: Path) -> dict[str, Any]:
    from mcchain.parallel import plan_chunks

    return {
        "id": folder.name,
        "status": RUNNING,
        "scene": job.scene_name,
        "scene_file": str(scene_path.resolve()),
        "samples": job.nsample,
        "seed": job.seed,
        "chunk_size": job.chunk_size,
        "chunks": len(plan_chunks(job.nsample, job.chunk_size)),
        "storage": {
            "history_dtype": job.history_dtype,
            "compression": job.compression,
            "complevel": job.complevel,
        },
        "start": _now(),
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
    }


def _compute(
    job: Job,
    parts_dir: Path,
    attrs: Mapping[str, Any],
    *,
    dask: str | None,
    threads: int | None,
    solve: SolveFn | None,
    progress: bool | None,
    live: _LiveRun | None = None,
) -> ExecutionStats:
    """Solve the chunks that have no part file yet, writing each as a part file (and
    streaming the ``--rerun`` samples they hold to ``live``)."""
    from mcchain.ensemble.io import list_parts, write_part
    from mcchain.ensemble.registry import build_dataset
    from mcchain.parallel import ExecutionStats, Progress, plan_chunks, run_dask, run_local

    chunks = plan_chunks(job.nsample, job.chunk_size)
    done = {(p.start, p.stop) for p in list_parts(parts_dir)}
    if done - set(chunks):
        raise RunError(f"{parts_dir}: part files do not match chunk size {job.chunk_size}")
    missing = [c for c in chunks if c not in done]
    log.info(
        "scene %s: %d samples, %d chunks of %d, %d to compute",
        job.scene_name,
        job.nsample,
        len(chunks),
        job.chunk_size,
        len(missing),
    )
    if live is not None:
        live.open(missing)
    if not missing:
        return ExecutionStats(scheduler="none (all chunks present)")

    def sink(outputs: dict[str, Any], start: int, stop: int) -> None:
        chunk = job.model.select(start, stop)
        ds = build_dataset(
            outputs, chunk, start=start, history_dtype=job.history_dtype, attrs=attrs
        )
        write_part(ds, parts_dir, start, stop)

    observe = live.observe if live is not None else None
    bar = Progress(len(chunks), len(done), enabled=progress)
    try:
        if dask:
            return run_dask(
                job.model,
                job.scene,
                missing,
                sink,
                address=dask,
                workers=threads,
                history_dtype=job.history_dtype,
                solve=solve,
                progress=bar,
                observe=observe,
            )
        return run_local(
            job.model,
            job.scene,
            missing,
            sink,
            history_dtype=job.history_dtype,
            threads=threads,
            solve=solve,
            progress=bar,
            observe=observe,
        )
    finally:
        bar.close()


def _complete(
    job: Job,
    record: dict[str, Any],
    session: dict[str, Any],
    stats: ExecutionStats,
    merged: MergeStats,
    counts: dict[str, int],
    total: float,
    prepare_seconds: float,
) -> None:
    """Fill ``run.json``'s timings, throughput, merge figures and status counts."""
    timings = {
        "prepare": prepare_seconds,
        "warmup": stats.warmup,
        "compute": stats.compute,
        "kernel": stats.kernel,
        "write": stats.write,
        "merge": merged.seconds,
        "total": total,
    }
    session.update(
        end=_now(),
        status=COMPLETED,
        chunks_computed=stats.chunks,
        samples_computed=stats.samples,
        scheduler=stats.scheduler,
        threads=stats.threads,
        timings=timings,
    )
    summed: dict[str, float] = {}
    for s in record["sessions"]:
        for key, value in (s.get("timings") or {}).items():
            summed[key] = summed.get(key, 0.0) + float(value)
    samples_per_s = stats.samples / stats.compute if stats.compute > 0 else None
    steps = job.steps_per_sample
    busy = stats.workers * (stats.compute + merged.seconds)
    record.update(
        status=COMPLETED,
        end=session["end"],
        threads=stats.threads,
        scheduler=stats.scheduler,
        timings=summed,
        wall_time=summed.get("total"),
        status_counts=counts,
        throughput={
            "samples_per_s": samples_per_s,
            "steps_per_sample": steps,
            "instance_steps_per_s": samples_per_s * steps if samples_per_s and steps else None,
            "outside_kernel_share": 1.0 - stats.kernel / busy if busy > 0 else None,
        },
        merge={
            "bytes_in": merged.bytes_in,
            "bytes_out": merged.bytes_out,
            "seconds": merged.seconds,
            "mb_per_s": merged.throughput,
            "compression": job.compression,
            "note": merged.note or None,
        },
    )
    if stats.worker_info:
        record["workers"] = stats.worker_info


def execute(
    job: Job,
    folder: Path,
    record: dict[str, Any],
    *,
    argv: Sequence[str] = (),
    dask: str | None = None,
    threads: int | None = None,
    solve: SolveFn | None = None,
    progress: bool | None = None,
    keep_parts: bool = False,
    prepare_seconds: float = 0.0,
    rerun: LiveOptions | None = None,
) -> RunResult:
    """Compute the missing chunks of a run folder, merge them, and complete ``run.json``.

    Phases timed in ``run.json["timings"]`` (seconds, summed over sessions): ``prepare``
    (load, compile, check), ``warmup`` (kernel compile/cache load, cluster start),
    ``compute`` (the chunk loop, writes overlapping), ``kernel`` (time inside the solver),
    ``write`` (part files), ``merge``, ``total``.

    Throughput (this session): ``samples_per_s`` = samples computed / ``compute``;
    ``instance_steps_per_s`` = that × integration steps per sample (``[simulate]`` only);
    ``outside_kernel_share`` = 1 − ``kernel`` / (workers × (``compute`` + ``merge``)), the
    share of the chunk loop and merge spent outside the solver (I/O, merge, Python; compile
    excluded). With Dask, ``kernel`` sums the workers' solver time and workers is their count.

    With ``rerun``, the selected samples of the chunks this session computes are streamed
    to rerun as their chunks arrive (see :class:`_LiveRun`; ``run.json`` records it in the
    session's ``rerun`` entry). The stream is closed before the merge.

    A failure or Ctrl-C marks the run ``FAILED`` (finished part files stay) and re-raises
    with a note naming the folder to resume.
    """
    from mcchain.ensemble.io import list_parts, merge_parts, remove_temporaries

    t_start = time.perf_counter()
    session: dict[str, Any] = {"argv": list(argv), "start": _now(), "end": None, "pid": os.getpid()}
    record.update(status=RUNNING, end=None, error=None, pid=os.getpid())
    record["sessions"].append(session)
    versions = software_versions()
    if record.get("versions") and record["versions"] != versions:
        # The ensemble records the versions of the run's first session.
        session["versions"] = versions
        versions = record["versions"]
    parts_dir = folder / PARTS
    parts_dir.mkdir(exist_ok=True)
    with run_lock(folder), _run_log(folder):
        write_record(folder, record)
        try:
            if "versions" in session:
                log.warning("resumed with other software versions: %s", session["versions"])
            removed = remove_temporaries(parts_dir) + remove_temporaries(folder)
            if removed:
                log.info("removed %d temporary files left by an interrupted run", removed)
            live = None
            if rerun is not None:
                live = _LiveRun(rerun, job, folder, session.setdefault("rerun", {}))
            try:
                stats = _compute(
                    job,
                    parts_dir,
                    job.attributes(versions),
                    dask=dask,
                    threads=threads,
                    solve=solve,
                    progress=progress,
                    live=live,
                )
            finally:
                if live is not None:
                    live.close()
            merged = merge_parts(
                list_parts(parts_dir),
                folder / ENSEMBLE,
                compression=job.compression,
                complevel=job.complevel,
                nsample=job.nsample,
            )
            log.info(
                "merged %d parts into %s: %.1f MB -> %.1f MB in %.2f s (%.0f MB/s)",
                merged.nparts,
                ENSEMBLE,
                merged.bytes_in / 1e6,
                merged.bytes_out / 1e6,
                merged.seconds,
                merged.throughput,
            )
            counts = _status_counts(folder / ENSEMBLE)
        except BaseException as exc:
            session["end"] = record["end"] = _now()
            record["status"] = session["status"] = FAILED
            message = "interrupted" if isinstance(exc, KeyboardInterrupt) else str(exc).strip()
            record["error"] = message or type(exc).__name__
            session["timings"] = {"total": time.perf_counter() - t_start + prepare_seconds}
            log.error("run failed: %s\n%s", record["error"], traceback.format_exc())
            write_record(folder, record)
            exc.add_note(f"run folder: {folder} (complete it with: mcchain run --resume {folder})")
            raise
        total = time.perf_counter() - t_start + prepare_seconds
        _complete(job, record, session, stats, merged, counts, total, prepare_seconds)
        write_record(folder, record)
        log.info("run completed: %s", json.dumps(counts))
        if not keep_parts:
            for part in list_parts(parts_dir):
                part.path.unlink()
            with contextlib.suppress(OSError):
                parts_dir.rmdir()
    return RunResult(folder, record)


def start_run(
    scene_path: str | Path,
    *,
    samples: int | None = None,
    seed: int | None = None,
    chunk_size: int | None = None,
    out: str | Path = DEFAULT_OUT,
    run_dir: str | Path | None = None,
    dask: str | None = None,
    threads: int | None = None,
    argv: Sequence[str] | None = None,
    loader: Loader | None = None,
    solve: SolveFn | None = None,
    progress: bool | None = None,
    keep_parts: bool = False,
    rerun: LiveOptions | None = None,
) -> RunResult:
    """Run a scene into a new run folder (``mcchain run``).

    Every check (scene, kinematics, arguments, ``run_dir``, ``--rerun`` indices) happens
    before the folder is created: a bad input raises ``SceneError``/``RunError`` and writes
    nothing. ``rerun`` streams samples to rerun while the run goes (:class:`LiveOptions`).
    """
    t0 = time.perf_counter()
    if run_dir is not None:
        check_new_run_dir(run_dir)
    _check_threads(threads, dask)
    job = prepare_job(scene_path, samples=samples, seed=seed, chunk_size=chunk_size, loader=loader)
    check_live(rerun, job.nsample)
    prepare_seconds = time.perf_counter() - t0
    folder = create_run_folder(out, job.scene_name, run_dir)
    with open(folder / SCENE_COPY, "w", encoding="utf-8", newline="") as f:
        f.write(job.scene_text)
    argv = list(sys.argv if argv is None else argv)
    record = _new_record(job, folder, argv, Path(scene_path))
    return execute(
        job,
        folder,
        record,
        argv=argv,
        dask=dask,
        threads=threads,
        solve=solve,
        progress=progress,
        keep_parts=keep_parts,
        prepare_seconds=prepare_seconds,
        rerun=rerun,
    )


def resume_run(
    run: str | Path,
    *,
    dask: str | None = None,
    threads: int | None = None,
    argv: Sequence[str] | None = None,
    loader: Loader | None = None,
    solve: SolveFn | None = None,
    progress: bool | None = None,
    keep_parts: bool = False,
    rerun: LiveOptions | None = None,
) -> RunResult:
    """Complete an interrupted or failed run: compute only its missing chunks.

    The scene is read back from the folder's ``scene.toml`` with the recorded sample count,
    seed and chunk size, so the final ``ensemble.nc`` equals an uninterrupted run's.
    ``rerun`` streams the selected samples of the chunks computed now (those computed
    before are named in the summary: replay them with ``mcchain show``).
    """
    t0 = time.perf_counter()
    folder = resolve_run(run)
    record = read_record(folder)
    if record.get("status") == COMPLETED and (folder / ENSEMBLE).exists():
        raise RunError(f"{run}: already completed")
    if is_locked(folder):
        raise RunError(f"{run}: the run is being executed by another process")
    _check_threads(threads, dask)
    job = prepare_job(
        folder / SCENE_COPY,
        samples=int(record["samples"]),
        seed=record.get("seed"),
        chunk_size=int(record["chunk_size"]),
        loader=loader,
    )
    if job.nsample != record["samples"]:
        raise RunError(
            f"{run}: scene.toml gives {job.nsample} samples, run.json {record['samples']}"
        )
    check_live(rerun, job.nsample)
    argv = list(sys.argv if argv is None else argv)
    return execute(
        job,
        folder,
        record,
        argv=argv,
        dask=dask,
        threads=threads,
        solve=solve,
        progress=progress,
        keep_parts=keep_parts,
        prepare_seconds=time.perf_counter() - t0,
        rerun=rerun,
    )


def _check_threads(threads: int | None, dask: str | None) -> None:
    _check_positive("--threads", threads)
    if dask is not None and dask != "local" and not re.match(r"^[a-z0-9+]+://", dask):
        raise RunError(
            f"--dask: expected 'local' or a scheduler address like tcp://host:8786, got {dask!r}"
        )
    if threads is not None and dask is None:
        import numba

        limit = int(numba.config.NUMBA_NUM_THREADS)  # type: ignore[attr-defined]
        if threads > limit:
            raise RunError(f"--threads: at most {limit} on this machine, got {threads}")


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
