"""``mcchain`` command line: a thin front end, and the one place that parses arguments.

Commands: ``run`` (:mod:`mcchain.runner.plan`), ``validate``, ``runs`` (:mod:`mcchain.runner.runs`),
``show`` (:func:`mcchain.viz.show.show_run`), ``report``
(:func:`mcchain.viz.report_page.write_report`); the benchmarks are scripts in ``benchmarks/``.
A bad input (``SceneError``, ``RunError``, a bad
flag) prints one line ``mcchain: error: <message>`` on stderr and exits with 2, having
written nothing; usage errors of ``show`` and ``report`` name the command
(``mcchain show: ...``). A run that fails once started (a full disk, its folder removed,
``RunFailed``) prints one such line and exits with 1, keeping its finished chunks; a run
that completes with every sample failed prints its folder, then one such line with the
status counts, and exits with 3. ``verdict`` (:mod:`mcchain.decision.verdict`) exits 0 when
every requirement passes, 1 when one fails, 4 when none fails but one is undecided.

The package: :mod:`~mcchain.cli.parser` (the arguments), :mod:`~mcchain.cli.commands` (a
handler per command), :mod:`~mcchain.cli.describe` (what ``validate`` prints). It imports only
the standard library at import time, and building the parser does too (``mcchain runs`` must
stay fast): ``show``'s arguments, whose help lists the status flags, are added when ``show`` is
parsed.
"""

from __future__ import annotations

import atexit
import contextlib
import gc
import os
import sys
from collections.abc import Sequence
from typing import NoReturn

from mcchain.cli import commands
from mcchain.cli.commands import EXIT_FAILED, EXIT_INTERRUPTED, HANDLERS, fail
from mcchain.errors import McchainError, RunFailed

GC_FIRST_GENERATION = 50_000
"""Allocations (of container objects) between two collections of the cyclic collector's
youngest generation in the ``mcchain`` process (Python's default: 700)."""


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``mcchain`` console script; returns the exit code."""
    from mcchain.cli.parser import NAMED_ERRORS, UsageError, build_parser

    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser()
    try:
        args, extra = parser.parse_known_args(argv)
    except UsageError as exc:
        return fail(str(exc))
    command = args.command
    if extra:
        message = f"unrecognized arguments: {' '.join(extra)}"
        return fail(f"mcchain {command}: {message}" if command in NAMED_ERRORS else message)
    try:
        return HANDLERS[command](args)
    except RunFailed as exc:
        return fail(str(exc).splitlines()[0], EXIT_FAILED)
    except McchainError as exc:
        return fail(str(exc).splitlines()[0] if str(exc) else type(exc).__name__)
    except KeyboardInterrupt as exc:
        notes = getattr(exc, "__notes__", [])
        print("; ".join(["mcchain: interrupted", *notes]), file=sys.stderr)
        return EXIT_INTERRUPTED


def console_main() -> NoReturn:
    """Entry of the ``mcchain`` console script and of ``python -m mcchain.cli``: :func:`main`,
    then the exit, without tearing the interpreter down object by object.

    That teardown freed numba's loaded kernels one by one: 0.3-0.4 s after every command
    that used them, a third of a warm ``validate``. The exit handlers (log files, rerun
    recordings, temporary folders) still run and the streams are flushed first, so nothing
    written is lost. An exception :func:`main` does not handle exits the usual way.

    ``validate`` and ``run`` may run their kernels interpreted here
    (:func:`mcchain.cli.commands._interpret_for`, :mod:`mcchain.compiled.first_run`), never when
    :func:`main` is called in a process that may go on to solve.
    """
    commands._may_interpret = sys.argv[1:2] in (["validate"], ["run"])
    # The cyclic collector's first generation at 50,000 objects instead of 700: the start's
    # imports (numba, scipy.special, pydantic) and the scene allocate long-lived objects by
    # the hundred thousand, which the default collects again and again for nothing
    # (benchmarks/results/verdict/verdict.md). The process's own setting, as mypy's: a
    # library call (tests, notebooks) keeps Python's.
    gc.set_threshold(GC_FIRST_GENERATION, 20, 20)
    code = main()
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(OSError, ValueError):  # a closed pipe: nothing to flush to
            stream.flush()
    os._exit(code)
