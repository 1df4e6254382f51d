"""The plan stage of a run: starting, resuming and extending one.

:func:`start_run` (``mcchain run SCENE``) checks everything, prepares the job (scene,
model, resources, disk), creates the run folder and its ``run.json``; :func:`resume_run`
(``mcchain run --resume RUN``) plans the chunks an interrupted run lacks; :func:`extend_run`
(``--extend``) adds samples to a completed one. Each makes a
:class:`mcchain.runner.pipeline.Plan` (the job, the folder, the observers in order:
:func:`mcchain.runner.observers.observers_for`) and runs it
(:func:`mcchain.runner.pipeline.run_pipeline`).

Nothing here depends on timing: ``ensemble.nc`` holds no timestamps or host names, so the
same scene and seed give a byte-identical file whatever the chunk size, thread count or
scheduler, and a resumed run equals an uninterrupted one.

This module imports only the standard library at import time, and the modules of each
stage when it comes (``mcchain runs`` and ``mcchain --help`` import it): numpy, xarray,
netCDF4, numba, the solvers and rerun are imported when a run executes.
"""

from __future__ import annotations

import logging
import os
import re
import sys
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from mcchain.errors import McchainError, RunError, check_positive
from mcchain.runner import DEFAULT_OUT

if TYPE_CHECKING:
    from mcchain.compiled.first_run import FirstRun
    from mcchain.runner.job import Job, Loader
    from mcchain.runner.pipeline import RunResult
    from mcchain.runner.steps import Observer, SolveFn
    from mcchain.viz.live import LiveOptions


log = logging.getLogger("mcchain")


DAMAGED_ENSEMBLE = "ensemble.damaged.nc"
"""Where ``--remerge`` keeps the ``ensemble.nc`` it replaces."""


def start_run(
    scene_path: str | Path,
    *,
    samples: int | None = None,
    seed: int | None = None,
    chunk_size: int | None = None,
    out: str | Path | None = None,
    run_dir: str | Path | None = None,
    dask: str | None = None,
    threads: int | None = None,
    argv: Sequence[str] | None = None,
    loader: Loader | None = None,
    solve: SolveFn | None = None,
    progress: bool | None = None,
    keep_parts: bool = False,
    rerun: LiveOptions | None = None,
    first_run: FirstRun | None = None,
    background_off: str | None = None,
) -> RunResult:
    """Run a scene into a new run folder (``mcchain run``) under ``out`` (default
    ``runs``), or exactly ``run_dir``.

    Every check (scene, kinematics, arguments, ``run_dir``, ``--rerun`` indices, the disk
    space: :func:`mcchain.runner.resources.check_disk`) happens before the folder is created: a
    bad input raises ``SceneError``/``RunError`` and writes nothing. ``rerun`` streams
    samples to rerun while the run goes (:class:`LiveOptions`).

    ``first_run``: this process runs the kernels interpreted (:mod:`mcchain.compiled.first_run`,
    the console script only): a background process compiles them for the next runs, and
    should the interpreted kernels raise, the process becomes the compiled run (or its
    resume, once the folder exists). ``background_off``: what switched that background
    compile off (``--no-background-compile``, the user's config file), or None
    (:func:`mcchain.compiled.background.why_not_background` has the other reasons).
    """
    t0 = time.perf_counter()
    out = DEFAULT_OUT if out is None else out
    if run_dir is not None:
        from mcchain.runner.runs import check_new_run_dir

        check_new_run_dir(run_dir)
    _check_threads(threads, dask)
    folder: Path | None = None
    from mcchain.compiled.ready import Kernels

    kernels = Kernels.for_run(
        scene_path,
        seed,
        samples,
        compiled=loader is None and solve is None and dask is None,  # the real kernels, here
        first_run=first_run,
    )
    try:
        from mcchain.runner.job import prepare_job

        job = prepare_job(
            scene_path, samples=samples, seed=seed, chunk_size=chunk_size, loader=loader
        )
        grow = None
        if getattr(getattr(job.scene, "sample", None), "until", None) is not None:
            from mcchain.decision.until import sequential_job

            job, grow = sequential_job(
                job, Path(scene_path), seed=seed, chunk_size=chunk_size, loader=loader
            )
        if rerun is not None:
            from mcchain.viz.live import check_live

            check_live(rerun, job.model.nsample)
            job = job.with_solved_histories()
        from mcchain.runner.resources import check_disk

        check_disk(job.disk, out if run_dir is None else run_dir)
        warnings, notes = kernels.after_checks(
            job.kernels, job.nsample, scene_path, seed, samples, background_off
        )
        job.warnings.extend(warnings)
        job.notes.extend(notes)
        for line in job.warnings:
            print(f"warning: {line}", file=sys.stderr)
        for line in job.notes:
            print(f"note: {line}", file=sys.stderr)
        from mcchain.runner.observers import observers_for, solve_steps_for

        observers = observers_for(job, progress=progress, rerun=rerun, grow=grow)
        solve_steps = solve_steps_for(job, solve)
        prepare_seconds = time.perf_counter() - t0
        from mcchain.runner.runs import create_run

        argv = list(sys.argv if argv is None else argv)
        folder, record = create_run(job, scene_path, argv, out, run_dir)
        if grow is not None:
            record["until"] = grow.describe()
        from mcchain.runner.pipeline import Plan, run_pipeline

        plan = Plan(
            job,
            folder,
            record,
            record["versions"],
            observers,
            kernels,
            dask=dask,
            threads=threads,
            solve=solve,
            solve_steps=solve_steps,
            argv=argv,
            prepare_seconds=prepare_seconds,
            keep_parts=keep_parts,
        )
        return run_pipeline(plan)
    except Exception as exc:
        if kernels.first_run is None or isinstance(exc, (McchainError, OSError)):
            raise
        from mcchain.compiled.first_run import run_compiled

        run_compiled(resume=folder, reason=exc)
    finally:
        if kernels.ahead is not None:  # its helper, if the run failed before its warm-up
            kernels.stop()


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
    remerge: bool = False,
) -> RunResult:
    """Complete an interrupted or failed run: compute only its missing chunks.

    The scene is read back from the folder's ``scene.toml`` with the recorded sample count,
    seed and chunk size, so the final ``ensemble.nc`` equals an uninterrupted run's.
    ``rerun`` streams the selected samples of the chunks computed now (those computed
    before are named in the summary: replay them with ``mcchain show``).

    ``remerge`` rebuilds ``ensemble.nc`` of any run (a damaged one is kept aside as
    ``ensemble.damaged.nc``): the chunks whose part files are gone (a completed run keeps
    none) are computed again, and runs are deterministic, so the file is the one the run
    wrote first.

    A resume whose missing part files and merge would not fit in the free space is refused
    before anything changes (:func:`mcchain.runner.resources.check_disk`).
    """
    from mcchain.decision.until import keep_sequential, sequential_job
    from mcchain.ensemble.io import DamagedEnsemble, open_ensemble
    from mcchain.runner.observers import observers_for
    from mcchain.runner.resources import check_disk
    from mcchain.runner.runs import (
        COMPLETED,
        ENSEMBLE,
        SCENE_COPY,
        is_locked,
        missing_samples,
        read_record,
        resolve_run,
    )
    from mcchain.viz.live import check_live

    t0 = time.perf_counter()
    folder = resolve_run(run)
    record = read_record(folder)
    if is_locked(folder):
        raise RunError(f"{run}: the run is being executed by another process")
    ensemble = folder / ENSEMBLE
    if record.get("status") == COMPLETED and ensemble.exists() and not remerge:
        try:
            open_ensemble(ensemble, dask=False).close()
        except DamagedEnsemble as exc:
            raise RunError(f"{run}: already completed, but {exc}") from None
        raise RunError(f"{run}: already completed")
    _check_threads(threads, dask)
    job = recorded_job(folder, record, loader=loader)
    if job.nsample != record["samples"]:
        raise RunError(
            f"{run}: scene.toml gives {job.nsample} samples, run.json {record['samples']}"
        )
    grow = None
    if record.get("extensions"):  # extended since: judged by the confidence sequence
        job = keep_sequential(job, record)
    elif record.get("until"):
        job, grow = sequential_job(
            job,
            folder / SCENE_COPY,
            seed=record.get("seed"),
            chunk_size=int(record["chunk_size"]),
            loader=loader,
            batch=int(record["until"]["batch"]),
            nsample=job.nsample,
        )
    job = keep_kernels(job, record.get("kernels"))
    check_same_study(job, folder, "--resume")
    check_live(rerun, job.nsample)
    if rerun is not None:
        job = job.with_solved_histories()
    check_disk(job.disk, folder, missing_samples(folder, record), retry="resume")
    if remerge and ensemble.exists():
        os.replace(ensemble, folder / DAMAGED_ENSEMBLE)
    observers = observers_for(job, progress=progress, rerun=rerun, grow=grow)
    extension = (record.get("extensions") or [{}])[-1]
    if extension and "end" not in extension:  # an interrupted --extend: its files go stale
        from mcchain.runner.stale import Extension

        observers.append(Extension(int(extension["from"])))
    return _run_existing(job, folder, record, observers, t0, dask, threads, solve, argv, keep_parts)


def _check_threads(threads: int | None, dask: str | None) -> None:
    """``--threads`` and ``--dask`` (dask installed, its scheduler answering), checked
    before anything is written."""
    check_positive("--threads", threads)
    if dask is not None and dask != "local" and not re.match(r"^[a-z0-9+]+://", dask):
        raise RunError(
            f"--dask: expected 'local' or a scheduler address like tcp://host:8786, got {dask!r}"
        )
    if dask is not None:
        from mcchain.runner.executors import check_scheduler

        check_scheduler(dask)
    if threads is not None and dask is None:
        import numba

        limit = int(numba.config.NUMBA_NUM_THREADS)  # type: ignore[attr-defined]
        if threads > limit:
            raise RunError(f"--threads: at most {limit} on this machine, got {threads}")


CONTINUABLE_DESIGNS = ("random", "sobol")
"""Designs whose sample i does not depend on the count, so a run can be continued."""


def extend_run(
    run: str | Path,
    samples: int,
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
    """Add ``samples`` samples to a completed run (``mcchain run --extend RUN --samples N``).

    The design is continued: samples ``n .. n + samples - 1`` are the ones a run of
    ``n + samples`` would have drawn (``random``: the same Philox stream; ``sobol``: the
    same scrambled sequence, continued), computed as new part files (chunked from ``n``)
    and merged with ``ensemble.nc`` into a new ``ensemble.nc``. The result is, variable by
    variable, the ensemble of one run with the total count. A design whose points depend on
    the count (``lhs``, ``saltelli``) is refused, as is a scene without ``[sample]``.

    The run keeps its kernels (``run.json["kernels"]``), so every sample of it is computed
    on one path. The old ``ensemble.nc`` stays in place until the merged one replaces it:
    an interrupted extension is completed by ``mcchain run --resume RUN``.
    """
    from mcchain.decision.until import keep_sequential
    from mcchain.ensemble.io import DamagedEnsemble, open_ensemble
    from mcchain.runner.observers import observers_for
    from mcchain.runner.resources import check_disk
    from mcchain.runner.runs import (
        COMPLETED,
        ENSEMBLE,
        is_locked,
        now,
        read_record,
        resolve_run,
        run_chunks,
    )
    from mcchain.viz.live import check_live

    t0 = time.perf_counter()
    check_positive("--samples", samples)
    folder = resolve_run(run)
    record = read_record(folder)
    if is_locked(folder):
        raise RunError(f"{run}: the run is being executed by another process")
    ensemble = folder / ENSEMBLE
    if record.get("status") != COMPLETED or not ensemble.exists():
        raise RunError(
            f"--extend: {run} is not completed (complete it first: mcchain run --resume {run})"
        )
    try:
        open_ensemble(ensemble, dask=False).close()
    except DamagedEnsemble as exc:
        raise RunError(f"--extend: {exc}") from None
    _check_threads(threads, dask)
    old = int(record["samples"])
    total = old + samples
    job = recorded_job(folder, record, samples=total, loader=loader)
    sample = getattr(job.scene, "sample", None)
    if sample is None:
        raise RunError("--extend: the scene has no [sample] section (one instance, no design)")
    design = getattr(sample, "design", "random")
    if design not in CONTINUABLE_DESIGNS:
        raise RunError(
            f'--extend: design "{design}" cannot be continued (its points depend on the '
            f"count); run the scene again with --samples {total}"
        )
    job = keep_kernels(job, record.get("kernels"))
    check_same_study(job, folder, "--extend")
    check_live(rerun, total)
    if rerun is not None:
        job = job.with_solved_histories()
    check_disk(job.disk, folder, samples, retry="extend")
    notes = [] if record.get("until") else extended_fixed_count_notes(job, record)
    record.setdefault("extensions", []).append({"from": old, "to": total, "start": now()})
    record["restarts"] = sorted({*record.get("restarts", []), old})
    record["samples"] = total
    record["chunks"] = len(run_chunks(record, job.chunk_size))
    job = keep_sequential(job, record)
    from mcchain.runner.stale import Extension

    observers = [*observers_for(job, progress=progress, rerun=rerun), Extension(old, notes)]
    return _run_existing(job, folder, record, observers, t0, dask, threads, solve, argv, keep_parts)


def check_same_study(job: Job, folder: Path, flag: str) -> None:
    """Refuse, before anything is computed, to add samples to a run whose files this
    version would not write alike: the merge compares the parts' study attributes
    (settings with every default resolved, software versions), so a run begun by another
    mcchain (whose settings lack a key added since) or under other package versions would
    be refused only after the new chunks were computed — and their samples would not be
    computed the way the run's were.

    Raises:
        RunError: naming the attributes or settings keys that differ.
    """
    from mcchain.ensemble.io import list_parts
    from mcchain.ensemble.study import file_attributes, study_differences
    from mcchain.runner.provenance import software_versions
    from mcchain.runner.runs import ENSEMBLE, PARTS

    written = [folder / ENSEMBLE] if (folder / ENSEMBLE).exists() else []
    written += [part.path for part in list_parts(folder / PARTS)[:1]]
    theirs = None
    for path in written:
        try:
            theirs = file_attributes(path)
            break
        except OSError:  # a damaged ensemble.nc (--remerge rebuilds it): the parts tell
            continue
    if theirs is None:
        return
    differences = study_differences(job.attributes(software_versions()), theirs)
    if differences:
        raise RunError(
            f"{flag}: {folder.name} was written by another mcchain or other packages than "
            f"run here ({'; '.join(differences)}): its new samples would not be computed as "
            "its samples were; continue it with the versions that began it, or run its "
            "scene.toml again"
        )


def extended_fixed_count_notes(job: Job, record: Mapping[str, Any]) -> list[str]:
    """The line an ``--extend`` of a fixed-count run with requirements prints (the first
    extension only): its verdicts now come from the confidence sequence
    (:func:`mcchain.decision.until.keep_sequential`)."""
    if record.get("extensions") or not getattr(job.scene, "requirement", None):
        return []
    n = int(record["samples"])
    return [
        f"--extend: the verdicts of this run now come from its confidence sequence, looked at "
        f"every {n} samples (the first look: the {n} it had): a Clopper-Pearson interval does "
        "not hold for a run extended until it decides (optional stopping), the sequence holds "
        "whenever it stops; its bounds are wider"
    ]


def _run_existing(
    job: Job,
    folder: Path,
    record: dict[str, Any],
    observers: Sequence[Observer],
    t0: float,
    dask: str | None,
    threads: int | None,
    solve: SolveFn | None,
    argv: Sequence[str] | None,
    keep_parts: bool,
) -> RunResult:
    """The pipeline of a run folder that exists (resumed or extended), whose checks passed
    (since ``t0``): its kernels are loaded or compiled at the warm-up."""
    from mcchain.compiled.ready import Kernels
    from mcchain.runner.observers import solve_steps_for
    from mcchain.runner.pipeline import Plan, run_pipeline
    from mcchain.runner.provenance import software_versions

    kernels = Kernels()
    kernels.after_checks(job.kernels, job.nsample)
    plan = Plan(
        job,
        folder,
        record,
        software_versions(),
        observers,
        kernels,
        dask=dask,
        threads=threads,
        solve=solve,
        solve_steps=solve_steps_for(job, solve),
        argv=list(sys.argv if argv is None else argv),
        prepare_seconds=time.perf_counter() - t0,
        keep_parts=keep_parts,
    )
    return run_pipeline(plan)


def recorded_job(
    folder: Path,
    record: Mapping[str, Any],
    *,
    samples: int | None = None,
    loader: Loader | None = None,
) -> Job:
    """The job of an existing run: its ``scene.toml`` with the recorded seed and chunk size,
    and ``samples`` samples (default the recorded count)."""
    from mcchain.runner.job import prepare_job
    from mcchain.runner.runs import SCENE_COPY

    return prepare_job(
        Path(folder) / SCENE_COPY,
        samples=int(record["samples"]) if samples is None else samples,
        seed=record.get("seed"),
        chunk_size=int(record["chunk_size"]),
        loader=loader,
    )


def keep_kernels(job: Job, kernels: str | None) -> Job:
    """``job`` integrating on ``kernels`` (the path a run took, ``run.json["kernels"]``):
    ``[simulate] kernels = "auto"`` chooses by the sample count, and a run that grew must not
    change path halfway."""
    sim = getattr(job.scene, "simulate", None)
    if kernels is None or sim is None or getattr(sim, "kernels", None) in (None, kernels):
        return job
    from dataclasses import replace

    from mcchain.runner.job import resolved_settings

    scene = job.scene.model_copy(update={"simulate": sim.model_copy(update={"kernels": kernels})})
    settings = resolved_settings(scene, job.nsample, job.seed)
    return replace(job, scene=scene, settings=settings, kernels=kernels)
