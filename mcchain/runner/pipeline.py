"""Executing a prepared run folder: compute the chunks it lacks, merge them, complete
``run.json``, or record why the run failed (:func:`execute`, which
:func:`mcchain.runner.plan.start_run`, ``resume_run`` and ``extend_run`` call; see its
docstring for the phases timed and the throughput recorded in ``run.json``).

Nothing here depends on timing: ``ensemble.nc`` holds no timestamps or host names, so the
same scene and seed give a byte-identical file whatever the chunk size, thread count or
scheduler, and a resumed run equals an uninterrupted one.

This module imports only the standard library at import time; numpy, xarray, netCDF4,
numba, the solvers and rerun are imported when a run executes.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import errno
import json
import logging
import os
import time
import traceback
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from mcchain.errors import RunError, RunFailed
from mcchain.runner.job import Job
from mcchain.runner.provenance import software_versions
from mcchain.runner.runs import (
    COMPLETED,
    ENSEMBLE,
    FAILED,
    PARTS,
    RUNNING,
    drop_lock,
    run_lock,
    run_log,
    write_record,
)
from mcchain.viz.live import LiveOptions, LiveRun, live_summary

if TYPE_CHECKING:
    from mcchain.compiled.ahead import CompileAhead
    from mcchain.ensemble.io import MergeStats
    from mcchain.runner.executors import ExecutionStats, SolveFn

log = logging.getLogger("mcchain")


def now() -> str:
    return _dt.datetime.now().astimezone().isoformat(timespec="seconds")


@dataclass
class RunResult:
    """What :func:`start_run` / :func:`resume_run` return."""

    folder: Path
    record: dict[str, Any]
    failed: int = 0
    """Samples carrying a failure flag (:data:`mcchain.status.FAILURE_BITS`)."""

    @property
    def all_failed(self) -> bool:
        """Whether every sample of the run failed (the CLI then exits with 3)."""
        return self.failed > 0 and self.failed == int(self.record["samples"])

    def counts_line(self) -> str:
        """``ok 0, diverged 10, ...``: the status counts that are not 0, ``ok`` always."""
        counts = self.record.get("status_counts") or {}
        return ", ".join(
            f"{k} {v}" for k, v in counts.items() if k != "samples" and (v or k == "ok")
        )

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
            f"end to end {t.get('total', 0):.2f} s: prepare {t.get('prepare', 0):.2f} s, "
            f"kernel compile or cache load {t.get('warmup', 0):.2f} s, compute "
            f"{t.get('compute', 0):.2f} s (in the kernels {t.get('kernel', 0):.2f} s), merge "
            f"{t.get('merge', 0):.2f} s",
            f"compute only: {tp.get('samples_per_s') or 0:,.0f} samples/s"
            + (
                f", {tp['instance_steps_per_s']:.3g} instance-steps/s"
                if tp.get("instance_steps_per_s")
                else ""
            ),
        ]
        until = r.get("until")
        if until and until.get("stopped"):
            looks = len(until.get("looks", []))
            lines.append(f"until decided: {until['stopped']} ({looks} looks, {until['method']})")
        live = r["sessions"][-1].get("rerun") if r.get("sessions") else None
        if live:
            lines.append(live_summary(live))
        lines += r.get("requirements") or []
        return lines


def _status_counts(path: Path) -> tuple[dict[str, int], int]:
    """Status counts of a merged ensemble, read block by block, and how many samples carry
    a failure flag."""
    import netCDF4
    import numpy as np

    from mcchain.status import FAILURE_BITS, counts

    total: dict[str, int] = {}
    failed = 0
    with netCDF4.Dataset(path) as nc:
        var = nc["status"]
        n = var.shape[0]
        for b0 in range(0, n, 1 << 20):
            block = np.asarray(var[b0 : min(b0 + (1 << 20), n)])
            for key, value in counts(block).items():
                total[key] = total.get(key, 0) + value
            failed += int(np.count_nonzero(block & FAILURE_BITS))
        total["samples"] = int(n)
    return total, failed


def _interpreted() -> bool:
    """Whether this process ran the kernels interpreted (:mod:`mcchain.compiled.first_run`)."""
    from mcchain.kernels import config

    return config.INTERPRETED


def kernel_compiler(job: Job) -> str:
    """What compiled the kernels this process runs, as ``run.json``'s sessions and the
    ensemble's attributes record it: ``"interpreted"`` (:mod:`mcchain.compiled.first_run`: plain
    Python, no compile), ``"native"`` (the generated lane kernels of a ``[simulate]`` on
    ``kernels = "lanes"`` through :mod:`mcchain.codegen.native`) or ``"numba"`` (the
    hand-written kernels, and the lane kernels with ``MCCHAIN_LANE_COMPILER=numba`` or
    where this NumPy's layout sends them to numba: their last bits may differ)."""
    if _interpreted():
        return "interpreted"
    kernels = job_kernels(job)
    if kernels is None or kernels == "loop":
        return "numba"
    from mcchain.codegen.native import lane_compiler

    return lane_compiler()


def _kernel_target(job: Job) -> dict[str, Any] | None:
    """The CPU the generated lane kernels were generated and compiled for (their text
    depends on its SIMD width: :func:`mcchain.codegen.layout.target_cpu`), or None where
    the run uses none."""
    kernels = job_kernels(job)
    if _interpreted() or kernels is None or kernels == "loop":
        return None
    import hashlib

    from mcchain.codegen.layout import LMAX, target_cpu

    name, features = target_cpu()
    digest = hashlib.sha256(features.encode()).hexdigest()[:16]
    return {"cpu": name, "features_sha256": digest, "lane_width": LMAX}


def job_kernels(job: Job) -> str | None:
    """The path that integrates the run's time histories (``[simulate] kernels``), or None."""
    sim = getattr(job.scene, "simulate", None)
    return None if sim is None else str(getattr(sim, "kernels", "lanes"))


def _compute(
    job: Job,
    parts_dir: Path,
    attrs: Mapping[str, Any],
    chunks: Sequence[tuple[int, int]],
    *,
    base: int = 0,
    dask: str | None,
    threads: int | None,
    solve: SolveFn | None,
    progress: bool | None,
    live: LiveRun | None = None,
    compile_ahead: CompileAhead | None = None,
) -> ExecutionStats:
    """Solve the ``chunks`` that have no part file yet and do not lie in the first ``base``
    samples (those ``ensemble.nc`` holds before ``--extend`` adds to it), writing each as a
    part file (and streaming the ``--rerun`` samples they hold to ``live``)."""
    from mcchain.decision.requirements import job_requirements
    from mcchain.ensemble.io import list_parts, write_part
    from mcchain.ensemble.registry import chunk_variables
    from mcchain.runner.executors import ExecutionStats, Progress, run_dask, run_local

    done = {(p.start, p.stop) for p in list_parts(parts_dir)}
    if done - set(chunks):
        raise RunError(f"{parts_dir}: part files do not match chunk size {job.chunk_size}")
    done |= {c for c in chunks if c[1] <= base}
    missing = [c for c in chunks if c not in done]
    log.info(
        "scene %s: %d samples, %d chunks of %d, %d to compute",
        job.scene_name,
        chunks[-1][1],
        len(chunks),
        job.chunk_size,
        len(missing),
    )
    if live is not None:
        live.open(missing)
    if not missing:
        return ExecutionStats(scheduler="none (all chunks present)")

    requirements = job_requirements(job)

    def sink(outputs: dict[str, Any], start: int, stop: int) -> None:
        chunk = job.model.select(start, stop)
        if requirements is not None:
            outputs = requirements.add_to(outputs)
        variables = chunk_variables(
            outputs,
            chunk,
            start=start,
            history_dtype=job.history_dtype,
            attrs=attrs,
            **(requirements.chunk_keywords() if requirements is not None else {}),
        )
        write_part(variables, parts_dir, start, stop)

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
            compile_ahead=compile_ahead,
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
        end=now(),
        status=COMPLETED,
        chunks_computed=stats.chunks,
        samples_computed=stats.samples,
        scheduler=stats.scheduler,
        threads=stats.threads,
        kernels_interpreted=_interpreted(),
        kernel_compiler=kernel_compiler(job),
        kernel_target=_kernel_target(job),
        timings=timings,
    )
    summed: dict[str, float] = {}
    for s in record["sessions"]:
        for key, value in (s.get("timings") or {}).items():
            summed[key] = summed.get(key, 0.0) + float(value)
    samples_per_s = stats.samples / stats.compute if stats.compute > 0 else None
    steps = stats.steps / stats.samples if stats.steps is not None and stats.samples else None
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
            "instance_steps_per_s": (
                stats.steps / stats.compute if stats.steps and stats.compute > 0 else None
            ),
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


def _requirement_lines(folder: Path) -> list[str]:
    """The requirements' answer in words (:func:`mcchain.decision.summary.summary_lines`),
    from the merged ensemble; ``mcchain export --requirements`` writes it with the CSVs."""
    from mcchain.decision.summary import allocations, design_of, summarize, summary_lines
    from mcchain.decision.until import sequential_settings
    from mcchain.ensemble.io import open_ensemble

    ds = open_ensemble(folder / ENSEMBLE)
    try:
        sequential = sequential_settings(ds.attrs)
        return summary_lines(summarize(ds), allocations(ds), design_of(ds), sequential)
    finally:
        ds.close()


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
    compile_ahead: CompileAhead | None = None,
    grow: GrowFn | None = None,
) -> RunResult:
    """Compute the missing chunks of a run folder, merge them, and complete ``run.json``.

    The run has ``run.json["samples"]`` samples, chunked by :func:`run_chunks`. While an
    ``--extend`` is unfinished, ``ensemble.nc`` holds the samples the run had before it
    (:func:`extension_base`): they are merged with the new parts, never computed again.
    ``grow(folder, record, nsample)`` (``[sample] until``) is asked after the chunks are computed
    whether the run needs more samples: it returns the new count, or None to stop.

    Phases timed in ``run.json["timings"]`` (seconds, summed over sessions): ``prepare``
    (load, compile, check), ``warmup`` (kernel compile/cache load, cluster start),
    ``compute`` (the chunk loop, writes overlapping), ``kernel`` (time inside the solver),
    ``write`` (part files), ``merge``, ``total``.

    Throughput (this session): ``samples_per_s`` = samples computed / ``compute``;
    ``steps_per_sample`` = the integration steps the samples took (as the solver counted
    them: fixed-step methods the steps to t_end, the last one shortened to land on it; rk45
    the accepted ones), summed, / samples computed; ``instance_steps_per_s`` = those steps
    / ``compute`` (both ``[simulate]`` only);
    ``outside_kernel_share`` = 1 − ``kernel`` / (workers × (``compute`` + ``merge``)), the
    share of the chunk loop and merge spent outside the solver (I/O, merge, Python; compile
    excluded). With Dask, ``kernel`` sums the workers' solver time and workers is their count.

    With ``rerun``, the selected samples of the chunks this session computes are streamed
    to rerun as their chunks arrive (see :class:`LiveRun`; ``run.json`` records it in the
    session's ``rerun`` entry). The stream is closed before the merge.

    A failure or Ctrl-C marks the run ``FAILED`` (finished part files stay) and re-raises
    with a note naming the folder to resume; a failure from outside (a full disk, the
    folder removed or made unwritable: :func:`_outside_failure`) raises :class:`RunFailed`
    instead, one line that says so, and ``run.json`` is left as it is if it cannot be written.
    """
    from mcchain.ensemble.io import Part, list_parts, merge_parts, remove_temporaries

    t_start = time.perf_counter()
    base = extension_base(folder, record)
    nsample = int(record["samples"])
    session: dict[str, Any] = {"argv": list(argv), "start": now(), "end": None, "pid": os.getpid()}
    record.update(status=RUNNING, end=None, error=None, pid=os.getpid())
    record["sessions"].append(session)
    versions = software_versions()
    if record.get("versions") and record["versions"] != versions:
        # The ensemble records the versions of the run's first session.
        session["versions"] = versions
        versions = record["versions"]
    parts_dir = folder / PARTS
    parts_dir.mkdir(exist_ok=True)
    with run_lock(folder), run_log(folder):
        write_record(folder, record)
        try:
            if "versions" in session:
                log.warning("resumed with other software versions: %s", session["versions"])
            removed = remove_temporaries(parts_dir) + remove_temporaries(folder)
            if removed:
                log.info("removed %d temporary files left by an interrupted run", removed)
            compiled_by = {"kernel_compiler": kernel_compiler(job)}
            attributes = {**job.attributes(versions), **compiled_by}
            live = None
            if rerun is not None:
                live = LiveRun(rerun, job, folder, session.setdefault("rerun", {}))
            try:
                stats = _compute(
                    job,
                    parts_dir,
                    attributes,
                    run_chunks(record, job.chunk_size),
                    base=base,
                    dask=dask,
                    threads=threads,
                    solve=solve,
                    progress=progress,
                    live=live,
                    compile_ahead=compile_ahead,
                )
            finally:
                if live is not None:
                    live.close()
            while grow is not None:
                more = grow(folder, record, nsample)
                if more is None:
                    break
                record["restarts"] = sorted({*record.get("restarts", []), nsample})
                nsample = record["samples"] = int(more)
                record["chunks"] = len(run_chunks(record, job.chunk_size))
                write_record(folder, record)
                added = _compute(
                    job,
                    parts_dir,
                    attributes,
                    run_chunks(record, job.chunk_size),
                    dask=dask,
                    threads=threads,
                    solve=solve,
                    progress=progress,
                )
                stats = _add_stats(stats, added)
            parts = list_parts(parts_dir)
            if base:
                parts = [Part(0, base, folder / ENSEMBLE), *parts]
            grown = base > 0 or bool(record.get("restarts")) or nsample != job.nsample
            merged = merge_parts(
                parts,
                folder / ENSEMBLE,
                compression=job.compression,
                complevel=job.complevel,
                nsample=nsample,
                attrs={**job.resized(nsample).attributes(versions), **compiled_by}
                if grown
                else None,
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
            counts, failed = _status_counts(folder / ENSEMBLE)
            if getattr(job.scene, "requirement", None):
                try:
                    record["requirements"] = _requirement_lines(folder)
                except Exception as error:  # the ensemble is complete: this must not fail the run
                    log.error("requirement summary failed: %s\n%s", error, traceback.format_exc())
                    record["requirements"] = [
                        f"requirements: the summary failed ({error}); see run.log"
                    ]
            total = time.perf_counter() - t_start + prepare_seconds
            _complete(job, record, session, stats, merged, counts, total, prepare_seconds)
            if record.get("extensions"):
                record["extensions"][-1].setdefault("end", session["end"])
            write_record(folder, record)
        except BaseException as exc:
            session["end"] = record["end"] = now()
            record["status"] = session["status"] = FAILED
            message = "interrupted" if isinstance(exc, KeyboardInterrupt) else str(exc).strip()
            outside = _outside_failure(job, folder, record, exc)
            record["error"] = str(outside) if outside else message or type(exc).__name__
            session["timings"] = {"total": time.perf_counter() - t_start + prepare_seconds}
            log.error("run failed: %s\n%s", record["error"], traceback.format_exc())
            try:
                write_record(folder, record)
            except OSError:
                if outside is None:
                    raise
            if outside is not None:
                raise outside from exc
            exc.add_note(f"run folder: {folder} (complete it with: mcchain run --resume {folder})")
            raise
        log.info("run completed: %s", json.dumps(counts))
        if not keep_parts:
            for part in list_parts(parts_dir):
                part.path.unlink()
            with contextlib.suppress(OSError):
                parts_dir.rmdir()
        drop_lock(folder)  # still held: a completed run keeps no lock file
    return RunResult(folder, record, failed)


GrowFn = Callable[[Path, dict[str, Any], int], "int | None"]
"""``grow(folder, record, nsample) -> new count or None``: whether a run whose first
``nsample`` samples are computed (as part files in ``folder``) needs more (``[sample]
until``); it may note what it saw in ``record`` (``run.json``), written next."""


def run_chunks(record: Mapping[str, Any], chunk_size: int) -> list[tuple[int, int]]:
    """The chunks of a run: ``run.json["samples"]`` in chunks of ``chunk_size``, the chunking
    starting again at every count the run had before it grew (``run.json["restarts"]``)."""
    from mcchain.runner.executors import plan_chunks

    return plan_chunks(int(record["samples"]), chunk_size, record.get("restarts", ()))


def extension_base(folder: Path, record: Mapping[str, Any]) -> int:
    """How many samples an unfinished ``--extend`` keeps from ``ensemble.nc`` (0 if none:
    no extension under way, or ``--remerge`` moved the file aside)."""
    extensions = record.get("extensions") or []
    if not extensions or "end" in extensions[-1] or not (Path(folder) / ENSEMBLE).exists():
        return 0
    return int(extensions[-1]["from"])


def _add_stats(a: ExecutionStats, b: ExecutionStats) -> ExecutionStats:
    """The figures of two executions of one session (``until`` batches), summed."""
    from dataclasses import replace

    last = b if b.chunks else a
    return replace(
        last,
        chunks=a.chunks + b.chunks,
        samples=a.samples + b.samples,
        warmup=a.warmup + b.warmup,
        compute=a.compute + b.compute,
        kernel=a.kernel + b.kernel,
        write=a.write + b.write,
        worker_info=a.worker_info + b.worker_info,
    )


DISK_FULL_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT})
"""``OSError`` numbers of a file system with no room left (full, or over the user's quota)."""


def _outside_failure(
    job: Job, folder: Path, record: Mapping[str, Any], exc: BaseException
) -> RunFailed | None:
    """The one-line :class:`RunFailed` of a run that failed for a reason outside the scene
    and the code, with the finished chunks kept: its folder removed or made unwritable, or
    its file system full (``ENOSPC``, or netCDF's "HDF error" while less space is free
    than the run still writes); None for any other failure (which is re-raised as is)."""
    if not isinstance(exc, Exception):  # Ctrl-C: "interrupted", exit 130
        return None
    resume = f"mcchain run --resume {folder}"
    if not folder.is_dir():
        return RunFailed(
            f"{folder}: the run folder was removed while the run went; its results are lost "
            "with it (run the scene again)"
        )
    parts_dir = folder / PARTS
    for place in (folder, parts_dir):
        if place.is_dir() and not os.access(place, os.W_OK | os.X_OK):
            return RunFailed(
                f"{place}: the run folder was made unwritable while the run went; the "
                f"finished chunks are kept: make it writable and complete it with: {resume}"
            )
    if not isinstance(exc, (OSError, RuntimeError)):
        return None
    from mcchain.ensemble.io import list_parts
    from mcchain.runner.resources import free_space, size_text

    free, _ = free_space(folder)
    missing = missing_samples(folder, record)
    need = None if job.disk is None else job.disk.peak(missing)
    full = isinstance(exc, OSError) and exc.errno in DISK_FULL_ERRNOS
    if not full and not ("HDF error" in str(exc) and need is not None and need > free):
        return None
    needed = "" if need is None else f"the run still needs up to {size_text(need)} and "
    done = len(list_parts(parts_dir)) if parts_dir.is_dir() else 0
    kept = f"{done} finished chunk{'' if done == 1 else 's'} kept"
    return RunFailed(
        f"{folder}: the disk is full: {needed}its file system has {size_text(free)} free; "
        f"{kept}: free space and complete it with: {resume}"
    )


def missing_samples(folder: Path, record: Mapping[str, Any]) -> int:
    """Samples of a run (``run.json["samples"]``) that neither a finished part file nor,
    during an ``--extend``, the ``ensemble.nc`` it extends holds."""
    from mcchain.ensemble.io import list_parts

    held = sum(p.stop - p.start for p in list_parts(folder / PARTS))
    return int(record["samples"]) - extension_base(folder, record) - held
