"""The ``mcchain`` commands: each takes the parsed arguments, calls the library and prints;
returns the exit code. Bad input raises (``McchainError``), which :func:`mcchain.cli.main`
turns into one line."""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
from collections.abc import Callable
from typing import Any

from mcchain.cli.describe import describe_initial_state, describe_model
from mcchain.errors import McchainError

EXIT_USAGE = 2
EXIT_FAILED = 1
EXIT_INTERRUPTED = 130
EXIT_ALL_FAILED = 3
"""``mcchain run``: the run completed, but every one of its samples failed."""


def fail(message: str, code: int = EXIT_USAGE) -> int:
    print(f"mcchain: error: {message}", file=sys.stderr)
    return code


def _cmd_cache(args: argparse.Namespace) -> int:
    from mcchain.compiled import report

    if args.cache_action == "status":
        print("\n".join(report.status_lines()))
    elif args.cache_action == "clear":
        print("\n".join(report.clear()))
    else:
        from mcchain.compiled.ahead import warm

        for scene in args.scenes:
            print(warm(scene))
    return 0


def _live_options(args: argparse.Namespace) -> Any:
    """``--rerun SAMPLES [--rerun-save FILE | --rerun-spawn]`` as ``viz.live.LiveOptions``
    (``None`` without ``--rerun``); raises ``RunError`` naming the flag."""
    from pathlib import Path

    from mcchain.errors import RunError

    if args.rerun is None:
        for flag, value in (("--rerun-save", args.rerun_save), ("--rerun-spawn", args.rerun_spawn)):
            if value:
                raise RunError(f"{flag}: requires --rerun SAMPLES")
        return None
    from mcchain.viz.live import LiveOptions, parse_rerun_samples

    if args.rerun_save is not None and args.rerun_spawn:
        raise RunError("--rerun-spawn: cannot be combined with --rerun-save (one sink)")
    if args.rerun_save is not None and not args.rerun_save.strip():
        raise RunError("--rerun-save: expected a file name")
    if args.rerun_spawn:
        from mcchain.viz.show import viewer_cannot_spawn

        refusal = viewer_cannot_spawn("--rerun-spawn")
        if refusal is not None:
            raise refusal
    save = Path(args.rerun_save) if args.rerun_save is not None else None
    return LiveOptions(parse_rerun_samples(args.rerun), save=save, spawn=bool(args.rerun_spawn))


def _cmd_run(args: argparse.Namespace) -> int:
    progress = False if args.quiet else None
    live = _live_options(args)
    argv = ["mcchain", *sys.argv[1:]]
    if args.extend is not None:
        conflicting = [
            flag
            for flag, value in (
                ("SCENE", args.scene),
                ("--seed", args.seed),
                ("--chunk-size", args.chunk_size),
                ("--out", args.out),
                ("--run-dir", args.run_dir),
                ("--resume", args.resume),
                ("--remerge", args.remerge or None),
            )
            if value is not None
        ]
        if conflicting:
            return fail(f"--extend: cannot be combined with {', '.join(conflicting)}")
        if args.samples is None:
            return fail("--extend: give the number of samples to add: --samples N")
        from mcchain.runner.plan import extend_run

        result = extend_run(
            args.extend,
            args.samples,
            dask=args.dask,
            threads=args.threads,
            argv=argv,
            progress=progress,
            rerun=live,
        )
    elif args.resume is not None:
        conflicting = [
            flag
            for flag, value in (
                ("SCENE", args.scene),
                ("--samples", args.samples),
                ("--seed", args.seed),
                ("--chunk-size", args.chunk_size),
                ("--out", args.out),
                ("--run-dir", args.run_dir),
            )
            if value is not None
        ]
        if conflicting:
            return fail(f"--resume: cannot be combined with {', '.join(conflicting)}")
        from mcchain.runner.plan import resume_run

        result = resume_run(
            args.resume,
            remerge=args.remerge,
            dask=args.dask,
            threads=args.threads,
            argv=argv,
            progress=progress,
            rerun=live,
        )
    else:
        if args.remerge:
            return fail("--remerge: only with --resume RUN")
        if args.scene is None:
            return fail("run: a SCENE.toml (or --resume RUN) is required")
        if args.out is not None and args.run_dir is not None:
            return fail("--run-dir: cannot be combined with --out")
        first_run = None
        if _may_interpret and args.dask is None:
            from mcchain.compiled.first_run import choose

            first_run = choose(args.scene, args.samples, args.seed)
        background_off = None
        if first_run is not None:
            from mcchain.cli.user_config import background_compile_off

            background_off = background_compile_off()
            if args.no_background_compile:
                background_off = "--no-background-compile"
        from mcchain.runner.plan import start_run

        result = start_run(
            args.scene,
            samples=args.samples,
            seed=args.seed,
            chunk_size=args.chunk_size,
            out=args.out,
            run_dir=args.run_dir,
            dask=args.dask,
            threads=args.threads,
            argv=argv,
            progress=progress,
            rerun=live,
            first_run=first_run,
            background_off=background_off,
        )
    from mcchain.runner.summary import run_summary, status_line

    for line in run_summary(result.record):
        print(line)
    print(result.folder)
    samples = result.record["samples"]
    if 0 < result.failed == samples:
        sys.stdout.flush()  # the folder, then the error line
        return fail(
            f"every one of the {samples} samples failed ({status_line(result.record)})",
            EXIT_ALL_FAILED,
        )
    return 0


VALIDATE_COMPILED = "MCCHAIN_VALIDATE_COMPILED"
"""``1``: ``mcchain validate`` checks with the compiled kernels (its fallback process)."""

_may_interpret = False
"""Set by :func:`mcchain.cli.console_main`: this process only validates or runs one scene, so its
kernels may run interpreted (``validate``: :func:`_interpret_for`; ``run``:
:mod:`mcchain.compiled.first_run`)."""


def _interpret_for(scene_path: Any) -> bool:
    """Whether ``validate`` runs the kernels interpreted: only in a process that does
    nothing else (:func:`mcchain.cli.console_main`), for a scene of at most
    :data:`INTERPRET_MAX_COORDINATES` coordinates."""
    if not _may_interpret or os.environ.get(VALIDATE_COMPILED) == "1":
        return False
    from mcchain.kernels.config import INTERPRET_MAX_COORDINATES, interpret_kernels
    from mcchain.scene import load_scene

    if 3 * len(load_scene(scene_path).body) > INTERPRET_MAX_COORDINATES:
        return False
    return interpret_kernels()


def _cmd_validate(args: argparse.Namespace) -> int:
    """Check the scene's nominal instance. From the command line, for a scene of moderate
    size, the kernels run interpreted (:func:`_interpret_for`: no numba, about 0.6 s less);
    should the interpreted check raise where numba would give inf or NaN (a degenerate
    instance), it runs again with the compiled kernels in a fresh process."""
    import numpy as np

    interpreted = _interpret_for(args.scene)
    # Interpreted, the kernels compute on numpy scalars, which warn where numba is silent.
    quiet = np.errstate(all="ignore") if interpreted else contextlib.nullcontext()
    try:
        with quiet:
            lines = _validation_lines(args.scene)
    except McchainError:
        raise
    except Exception:
        if not interpreted:
            raise
        import subprocess

        command = [sys.executable, "-m", "mcchain.cli", "validate", str(args.scene)]
        return subprocess.run(command, env={**os.environ, VALIDATE_COMPILED: "1"}).returncode
    print("\n".join(lines))
    return 0


def _validation_lines(scene_path: Any) -> list[str]:
    """What ``mcchain validate`` prints for a scene that passes its checks."""
    from mcchain.runner.job import default_loader
    from mcchain.solvers.statics import written_state

    scene, model = default_loader(scene_path, None, None)
    name = getattr(getattr(scene, "scene", None), "name", scene_path)
    written, assembled = written_state(scene)
    nominal = written if getattr(scene, "sample", None) is not None else None
    lines = [*describe_model(model, name, nominal), *describe_initial_state(written, assembled)]
    sim = getattr(scene, "simulate", None)
    if sim is not None:
        from mcchain.solvers.kernel_choice import choose_kernels

        choice = choose_kernels(sim, model.ndof, model.nsample)
        lines.append(f'simulate: {sim.method} on kernels = "{choice.kernels}" ({choice.reason})')
    lines.append(_disk_line(scene, model))
    warnings = model.meta.get("warnings") or []
    assert isinstance(warnings, list)
    return lines + [f"warning: {line}" for line in warnings]


def _disk_line(scene: Any, model: Any) -> str:
    """``validate``'s line on what a run of the scene writes (``mcchain run`` compares it
    with the free space; the free space is not printed here, so that the output depends on
    the scene only)."""
    from mcchain.runner.resources import estimate_disk

    estimate = estimate_disk(scene, model, model.nsample, scene.storage.chunk_size)
    assert estimate is not None
    return estimate.line()


def _cmd_runs(args: argparse.Namespace) -> int:
    from mcchain.runner.runs import format_runs, list_runs

    found = list_runs(args.out)
    if not found:
        print(f"no runs in {args.out}")
        return 0
    print(format_runs(found))
    return 0


def _cmd_show(args: argparse.Namespace) -> int:
    from pathlib import Path

    from mcchain.ensemble.queries import parse_samples
    from mcchain.errors import RunError
    from mcchain.viz.show import show_run

    if args.save is not None and Path(args.save).exists() and not args.force:
        raise RunError(f"--save: {args.save} already exists (add --force to overwrite it)")

    shown = show_run(
        args.run,
        parse_samples(args.samples),
        worst=args.worst,
        status=args.status,
        limit=args.limit,
        failed=args.failed,
        save=args.save,
        serve=args.serve,
        connect=args.connect,
        url=args.url,
        stdout=args.stdout,
        headless=args.headless,
        magnify=args.magnify,
        force_scale=args.force_scale,
    )
    print("samples " + ",".join(str(s) for s in shown))
    if args.save:
        print(args.save)
    return 0


def _cmd_report(args: argparse.Namespace) -> int:
    from mcchain.viz.report_page import write_report

    report = write_report(args.run, args.out)
    for name, reason in report.skipped.items():
        print(f"skipped {name}: {reason}")
    for path in report.written:
        print(path)
    return 0


def _cmd_export(args: argparse.Namespace) -> int:
    from mcchain.ensemble.export import export_run

    if args.requirements:
        from mcchain.decision.summary import export_requirements

        if args.out is not None:
            return fail("--out: not with --requirements (the files go to RUN/export/)")
        for path in export_requirements(args.run):
            print(path)
        if not args.csv:
            return 0
    if not args.csv:
        return fail("export: give the format: --csv or --requirements")
    print(export_run(args.run, args.out))
    return 0


def _cmd_check(args: argparse.Namespace) -> int:
    from mcchain.decision.check import check_run

    result = check_run(args.run, args.tighten, args.samples)
    for line in result.lines():
        print(line)
    print(result.csv)
    return 0


def _cmd_verdict(args: argparse.Namespace) -> int:
    from mcchain.decision.verdict import run_verdict

    table = run_verdict(args.run)
    for line in table.lines():
        print(line)
    return table.exit_code


def _cmd_rare(args: argparse.Namespace) -> int:
    from mcchain.decision.rare import rare_run

    if args.out is not None and args.run_dir is not None:
        return fail("--run-dir: cannot be combined with --out")
    result = rare_run(
        args.scene,
        args.requirement,
        per_level=args.per_level,
        seed=args.seed,
        out=args.out or "runs",
        run_dir=args.run_dir,
        argv=["mcchain", *sys.argv[1:]],
    )
    for line in result.lines():
        print(line)
    print(result.folder)
    return 0


EXIT_UNDECIDED = 4
"""``mcchain confirm``: the requirement is undecided inside the range (1: it fails)."""


def _cmd_confirm(args: argparse.Namespace) -> int:
    from mcchain.decision.confirm import confirm_run

    if args.out is not None and args.run_dir is not None:
        return fail("--run-dir: cannot be combined with --out")
    result = confirm_run(
        args.run,
        args.requirement,
        parameter=args.parameter,
        box=args.box,
        ranges=args.range,
        samples=args.samples,
        seed=args.seed,
        out=args.out or "runs",
        run_dir=args.run_dir,
        argv=["mcchain", *sys.argv[1:]],
        progress=False if args.quiet else None,
    )
    for line in result.lines():
        print(line)
    print(result.folder)
    return {"pass": 0, "fail": EXIT_FAILED}.get(result.decision, EXIT_UNDECIDED)


HANDLERS: dict[str, Callable[[argparse.Namespace], int]] = {
    "run": _cmd_run,
    "validate": _cmd_validate,
    "runs": _cmd_runs,
    "show": _cmd_show,
    "report": _cmd_report,
    "export": _cmd_export,
    "check": _cmd_check,
    "verdict": _cmd_verdict,
    "rare": _cmd_rare,
    "confirm": _cmd_confirm,
    "cache": _cmd_cache,
}
"""The handler of each command."""
