"""The store stage of a run: part files, their merge into ``ensemble.nc``, and ``run.json``.

:class:`Store` holds one session of a run folder: :meth:`Store.session_held` locks the
folder, copies the log to ``run.log``, records the session in ``run.json`` and lists the
chunks to compute (or, should anything fail, records why, keeping every finished part file);
:attr:`Store.write` writes a solved chunk as a part file (:class:`PartWriter`);
:meth:`Store.grow` adds samples; :meth:`Store.merge` streams the parts into ``ensemble.nc``;
:meth:`Store.complete` fills ``run.json``'s timings, throughput, merge figures and status
counts; a completed session then removes the merged parts and the lock.

What a part file holds is the :class:`PartWriter`'s choice: the chunk's variables from the
registry (:func:`mcchain.ensemble.registry.chunk_variables`) with the requirements'
``requirement_met`` (:meth:`mcchain.decision.requirements.RunRequirements.add_to`), and of
the time histories those ``[storage] histories`` keeps (:mod:`mcchain.ensemble.histories`).

This module imports only the standard library at import time.
"""

from __future__ import annotations

import contextlib
import errno
import json
import logging
import os
import time
import traceback
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from mcchain.errors import RunFailed
from mcchain.runner.runs import (
    COMPLETED,
    ENSEMBLE,
    FAILED,
    PARTS,
    RUNNING,
    close_completed,
    extension_base,
    missing_chunks,
    missing_samples,
    now,
    run_chunks,
    run_lock,
    run_log,
    write_record,
)
from mcchain.runner.steps import RunState

if TYPE_CHECKING:
    from mcchain.decision.requirements import RunRequirements
    from mcchain.ensemble.io import MergeStats
    from mcchain.ensemble.registry import ChunkVariables
    from mcchain.runner.executors import ExecutionStats
    from mcchain.runner.job import Job
    from mcchain.runner.steps import SolvedChunk

log = logging.getLogger("mcchain")


@dataclass(frozen=True)
class PartWriter:
    """Writes each solved chunk of ``job`` as a part file in ``parts_dir`` (atomically), with
    the global attributes ``attrs`` and the chunk's ``requirement_met`` when the job has
    ``requirements`` (:func:`mcchain.decision.requirements.job_requirements`); called on the
    writer thread of an in-process run."""

    job: Job
    parts_dir: Path
    attrs: Mapping[str, Any]
    requirements: RunRequirements | None = None

    def __call__(self, chunk: SolvedChunk) -> None:
        from mcchain.ensemble.io import write_part
        from mcchain.ensemble.registry import chunk_variables

        outputs: Mapping[str, Any] = chunk.outputs
        keywords: dict[str, Any] = {}
        if self.requirements is not None:
            outputs = self.requirements.add_to(outputs)
            keywords = self.requirements.chunk_keywords()
        variables = chunk_variables(
            outputs,
            self.job.model.select(chunk.start, chunk.stop),
            start=chunk.start,
            history_dtype=self.job.history_dtype,
            attrs=self.attrs,
            **keywords,
        )
        variables = kept_histories(variables, self.job.histories)
        write_part(variables, self.parts_dir, chunk.start, chunk.stop)


def kept_histories(chunk: ChunkVariables, mode: str) -> ChunkVariables:
    """A part file's variables with the time histories ``[storage] histories`` (``mode``)
    keeps: all (``chunk`` itself); none (nor the ``time`` coordinate); or, for
    ``"failed"``, each history's rows of the samples that
    :func:`~mcchain.ensemble.histories.replay_mask` picks, along ``history_sample``."""
    from mcchain.ensemble.histories import (
        HISTORY_MODES,
        HISTORY_SAMPLE,
        HISTORY_SAMPLE_ATTRS,
        is_history,
        replay_mask,
    )

    if mode not in HISTORY_MODES:
        raise ValueError(f"storage.histories: must be one of {HISTORY_MODES}, got {mode!r}")
    if mode == "all":
        return chunk
    if mode == "none":
        data_vars = {k: v for k, v in chunk.data_vars.items() if not is_history(v[0])}
        coords = {k: v for k, v in chunk.coords.items() if not is_history(v[0])}
        return replace(chunk, coords=coords, data_vars=data_vars)
    met = chunk.data_vars.get("requirement_met")
    keep = replay_mask(chunk.data_vars["status"][1], None if met is None else met[1])
    data_vars = {}
    for name, (dims, values, attrs) in chunk.data_vars.items():
        if is_history(dims):
            dims, values = (HISTORY_SAMPLE, *dims[1:]), values[keep]
        data_vars[name] = (dims, values, attrs)
    coords = dict(chunk.coords)
    if any(is_history(dims) for dims, _, _ in chunk.data_vars.values()):
        ids = chunk.coords["sample"][1][keep]
        coords[HISTORY_SAMPLE] = ((HISTORY_SAMPLE,), ids, dict(HISTORY_SAMPLE_ATTRS))
    return replace(chunk, coords=coords, data_vars=data_vars)


class Store:
    """The store of one session of a run folder (see the module's docstring).

    ``record`` is the run's ``run.json``; a new entry of its ``sessions`` records this one.
    ``versions``: the software versions of this process (the ensemble keeps those of the
    run's first session). ``kernel_compiler``: what compiled the kernels, stored in the
    ensemble's attributes. ``prepare_seconds`` (the checks and the job before the session)
    are counted in its timings. ``keep_parts``: keep the part files after the merge.
    """

    run: RunState
    """What the observers see of the session (made by :meth:`session_held`)."""
    write: PartWriter
    """Writes a solved chunk as a part file (made by :meth:`session_held`)."""
    merged: dict[str, Any]
    """``run.json["merge"]``: what the merge did (made by :meth:`merge`)."""

    def __init__(
        self,
        job: Job,
        folder: Path,
        record: dict[str, Any],
        versions: Mapping[str, str],
        *,
        kernel_compiler: str,
        argv: Sequence[str] = (),
        prepare_seconds: float = 0.0,
        keep_parts: bool = False,
    ) -> None:
        self.t_start = time.perf_counter()
        self.job, self.folder, self.record = job, folder, record
        self.versions = dict(versions)
        self.compiled_by = {"kernel_compiler": kernel_compiler}
        self.argv = list(argv)
        self.prepare_seconds = prepare_seconds
        self.keep_parts = keep_parts
        self.parts_dir = folder / PARTS
        self.base = 0

    @contextlib.contextmanager
    def session_held(self) -> Iterator[RunState]:
        """Open the session: the folder locked and its log copied to ``run.log`` while it
        runs, ``run.json`` written, what an interrupted run left removed; yields what the
        observers see of it, its first chunks to compute listed.

        A failure or Ctrl-C marks the run ``FAILED`` (finished part files stay) and
        re-raises with a note naming the folder to resume; a failure from outside (a full
        disk, the folder removed or made unwritable: :func:`outside_failure`) raises
        :class:`RunFailed` instead, one line that says so, and ``run.json`` is left as it is
        if it cannot be written. A session that completed removes its merged part files
        (unless kept) and its lock file."""
        from mcchain.decision.requirements import job_requirements
        from mcchain.ensemble.io import remove_temporaries

        folder, record, job = self.folder, self.record, self.job
        self.base = extension_base(folder, record)
        session: dict[str, Any] = {
            "argv": self.argv,
            "start": now(),
            "end": None,
            "pid": os.getpid(),
        }
        record.update(status=RUNNING, end=None, error=None, pid=os.getpid())
        record["sessions"].append(session)
        if record.get("versions") and record["versions"] != self.versions:
            # The ensemble records the versions of the run's first session.
            session["versions"] = self.versions
            self.versions = record["versions"]
        self.parts_dir.mkdir(exist_ok=True)
        with run_lock(folder), run_log(folder):
            write_record(folder, record)
            try:
                if "versions" in session:
                    log.warning("resumed with other software versions: %s", session["versions"])
                removed = remove_temporaries(self.parts_dir) + remove_temporaries(folder)
                if removed:
                    log.info("removed %d temporary files left by an interrupted run", removed)
                attributes = {**job.attributes(self.versions), **self.compiled_by}
                self.write = PartWriter(job, self.parts_dir, attributes, job_requirements(job))
                self.run = RunState(job, folder, record, session, int(record["samples"]))
                self.run.todo = missing_chunks(folder, record, job.chunk_size, self.base)
                yield self.run
            except BaseException as exc:
                session["end"] = record["end"] = now()
                record["status"] = session["status"] = FAILED
                message = "interrupted" if isinstance(exc, KeyboardInterrupt) else str(exc)
                outside = outside_failure(job, folder, record, exc)
                record["error"] = str(outside) if outside else message.strip() or type(exc).__name__
                session["timings"] = {"total": self.seconds()}
                log.error("run failed: %s\n%s", record["error"], traceback.format_exc())
                try:
                    write_record(folder, record)
                except OSError:
                    if outside is None:
                        raise
                if outside is not None:
                    raise outside from exc
                exc.add_note(
                    f"run folder: {folder} (complete it with: mcchain run --resume {folder})"
                )
                raise
            close_completed(folder, self.keep_parts)  # the lock still held

    def seconds(self) -> float:
        """The session's time so far, its preparation included."""
        return time.perf_counter() - self.t_start + self.prepare_seconds

    def grow(self, nsample: int) -> None:
        """The run has ``nsample`` samples from now on (``until`` asked for more): its
        chunking starts again at the count it had, and ``run.todo`` lists its new chunks."""
        record, run = self.record, self.run
        record["restarts"] = sorted({*record.get("restarts", []), run.nsample})
        run.nsample = record["samples"] = int(nsample)
        record["chunks"] = len(run_chunks(record, self.job.chunk_size))
        write_record(self.folder, record)
        run.todo = missing_chunks(self.folder, record, self.job.chunk_size, self.base)

    def merge(self) -> MergeStats:
        """Stream the part files (after the ``ensemble.nc`` an unfinished ``--extend`` adds
        to) into ``ensemble.nc``; a run that grew gets its final count's attributes."""
        from mcchain.ensemble.io import Part, list_parts, merge_parts

        job, folder, run = self.job, self.folder, self.run
        parts = list_parts(self.parts_dir)
        if self.base:
            parts = [Part(0, self.base, folder / ENSEMBLE), *parts]
        grown = self.base > 0 or bool(self.record.get("restarts")) or run.nsample != job.nsample
        merged = merge_parts(
            parts,
            folder / ENSEMBLE,
            compression=job.compression,
            complevel=job.complevel,
            nsample=run.nsample,
            attrs={**job.resized(run.nsample).attributes(self.versions), **self.compiled_by}
            if grown
            else None,
        )
        self.merged = {
            "bytes_in": merged.bytes_in,
            "bytes_out": merged.bytes_out,
            "seconds": merged.seconds,
            "mb_per_s": merged.throughput,
            "compression": job.compression,
            "note": merged.note or None,
        }
        log.info(
            "merged %d parts into %s: %.1f MB -> %.1f MB in %.2f s (%.0f MB/s)",
            merged.nparts,
            ENSEMBLE,
            merged.bytes_in / 1e6,
            merged.bytes_out / 1e6,
            merged.seconds,
            self.merged["mb_per_s"],
        )
        return merged

    def complete(
        self, stats: ExecutionStats, merged: MergeStats, kernels: Mapping[str, Any]
    ) -> int:
        """Fill ``run.json``'s timings, throughput, merge figures and status counts
        (``kernels``: what compiled them, for the session) and write it; returns how many
        samples carry a failure flag."""
        record, run = self.record, self.run
        session = run.session
        counts, failed = status_counts(self.folder / ENSEMBLE)
        timings = {
            "prepare": self.prepare_seconds,
            "warmup": stats.warmup,
            "compute": stats.compute,
            "kernel": stats.kernel,
            "write": stats.write,
            "merge": merged.seconds,
            "total": self.seconds(),
        }
        session.update(
            end=now(),
            status=COMPLETED,
            chunks_computed=stats.chunks,
            samples_computed=stats.samples,
            scheduler=stats.scheduler,
            threads=stats.threads,
            **kernels,
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
            merge=self.merged,
        )
        if stats.worker_info:
            record["workers"] = stats.worker_info
        if record.get("extensions"):
            record["extensions"][-1].setdefault("end", session["end"])
        write_record(self.folder, record)
        log.info("run completed: %s", json.dumps(counts))
        return failed


def status_counts(path: Path) -> tuple[dict[str, int], int]:
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


DISK_FULL_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT})
"""``OSError`` numbers of a file system with no room left (full, or over the user's quota)."""


def outside_failure(
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
