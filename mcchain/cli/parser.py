"""The ``mcchain`` argument parser: every command's arguments, and usage errors in one line.

Building the parser imports only the standard library (``mcchain runs`` must stay fast):
``show``'s arguments, whose help lists the status flags, are added when ``show`` is parsed.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from typing import Any, NoReturn

from mcchain import __version__

DESCRIPTION = (
    "Monte Carlo studies of planar linkages whose joints have clearance: sample clearances, "
    "masses, lengths and loads; get equilibria, natural frequencies, time histories, joint "
    "reactions and requirement verdicts for every instance."
)
"""The first line of ``mcchain --help``."""

NAMED_ERRORS = ("show", "report")
"""Commands whose usage errors start with ``mcchain <command>:``."""


class UsageError(Exception):
    pass


class Parser(argparse.ArgumentParser):
    """argparse that reports a usage error in one line, through :func:`main`.

    ``populate(parser)`` adds the arguments when the parser is first used (parsed or its
    help printed), so that building the whole parser imports nothing heavy;
    ``named_errors`` starts each error with the parser's ``prog``.
    """

    def __init__(
        self,
        *args: Any,
        populate: Callable[[argparse.ArgumentParser], None] | None = None,
        named_errors: bool = False,
        **kwargs: Any,
    ) -> None:
        super().__init__(*args, **kwargs)
        self._populate = populate
        self._named_errors = named_errors

    def populate(self) -> None:
        if self._populate is not None:
            add, self._populate = self._populate, None
            add(self)

    def parse_known_args(self, args: Any = None, namespace: Any = None) -> Any:
        self.populate()
        return super().parse_known_args(args, namespace)

    def format_usage(self) -> str:
        self.populate()
        return super().format_usage()

    def format_help(self) -> str:
        self.populate()
        return super().format_help()

    def error(self, message: str) -> NoReturn:
        raise UsageError(f"{self.prog}: {message}" if self._named_errors else message)


def positive(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {value}")
    return value


def seed(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {value}")
    return value


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(
        prog="mcchain",
        description=DESCRIPTION,
        epilog="Scene file format (every key, unit and default): docs/scenes.md",
    )
    parser.add_argument("--version", action="version", version=f"mcchain {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=Parser)

    run = sub.add_parser("run", help="run a scene into a new run folder, or resume a run")
    run.add_argument(
        "scene", nargs="?", metavar="SCENE.toml", help="scene file (format: docs/scenes.md)"
    )
    run.add_argument("--samples", type=positive, metavar="N", help="override [sample] count")
    run.add_argument("--seed", type=seed, metavar="S", help="override [sample] seed")
    run.add_argument(
        "--chunk-size", type=positive, metavar="K", help="samples per chunk ([storage])"
    )
    run.add_argument("--out", metavar="DIR", help="folder of run folders (default: runs)")
    run.add_argument("--run-dir", metavar="PATH", help="exact run folder (must not exist)")
    run.add_argument(
        "--dask", metavar="ADDRESS|local", help="run chunks on a Dask cluster ('local' starts one)"
    )
    run.add_argument(
        "--threads",
        type=positive,
        metavar="T",
        help="numba threads (in-process) or workers (--dask local)",
    )
    run.add_argument("--resume", metavar="RUN", help="complete an interrupted run folder")
    run.add_argument(
        "--extend",
        metavar="RUN",
        help="add --samples N samples to a completed run (the same design continued)",
    )
    run.add_argument(
        "--remerge",
        action="store_true",
        help="with --resume: rebuild the run's ensemble.nc (a damaged one is kept as "
        "ensemble.damaged.nc; chunks whose part files are gone are computed again, and runs "
        "are deterministic, so the file is the same)",
    )
    run.add_argument(
        "--rerun",
        metavar="SAMPLES",
        help="stream these samples (comma-separated global indices, e.g. 0,1) to rerun while "
        "the run goes (default sink: <run folder>/live.rrd)",
    )
    run.add_argument(
        "--rerun-save", metavar="FILE.rrd", help="--rerun: write the recording to this file"
    )
    run.add_argument(
        "--rerun-spawn", action="store_true", help="--rerun: spawn a rerun viewer instead"
    )
    run.add_argument("--quiet", action="store_true", help="no progress bar")
    run.add_argument(
        "--no-background-compile",
        action="store_true",
        help="on a cold cache, start no background process compiling the kernels for the next "
        "runs (for good: run.background_compile = false in ~/.config/mcchain/config.toml)",
    )

    validate = sub.add_parser(
        "validate", help="check a scene; print bodies, joints, constraint rows and dof"
    )
    validate.add_argument("scene", metavar="SCENE.toml")

    runs = sub.add_parser("runs", help="list past runs")
    runs.add_argument("--out", default="runs", metavar="DIR", help="folder of run folders")

    sub.add_parser(
        "show",
        help="replay samples of a run in the rerun viewer",
        description="replay samples of a run in the rerun viewer",
        populate=add_show_arguments,
        named_errors=True,
    )
    report = sub.add_parser(
        "report",
        help="draw a run's plots as PNG",
        description="draw a run's plots as PNG",
        named_errors=True,
    )
    report.add_argument("run", help="run folder (or its id under runs/)")
    report.add_argument("--out", metavar="DIR", help="folder of the PNG files (default RUN/report)")
    export = sub.add_parser(
        "export",
        help="write a run's per-sample results as a table",
        description="write one row per sample: sampled parameters, status, pulsations (rad/s "
        "and Hz), equilibria, contact summaries, the peaks tracked at every step (peak_*), "
        "and the largest stored point of each force history (max_stored_*)",
        named_errors=True,
    )
    export.add_argument("run", help="run folder (or its id under runs/)")
    export.add_argument("--csv", action="store_true", help="as CSV (the format)")
    export.add_argument(
        "--requirements",
        action="store_true",
        help="the [[requirement]] answer: RUN/export/requirements.csv, allocation.csv and "
        "requirements.txt",
    )
    export.add_argument("--out", metavar="FILE", help="the file (default RUN/export/samples.csv)")

    check = sub.add_parser(
        "check",
        help="re-solve the samples a numerical error could flip, tighter, and give the verdicts "
        "again",
        description="re-solve a run's samples with rtol/atol (or dt) TIGHTEN times tighter: "
        "samples spread evenly over the run, then every sample near a limit (or undefined); per "
        "requirement the verdict on the run's values and on the tightened ones, the flips, a "
        "bound on the flips not seen, and which tolerance to use (RUN/export/check.csv); the "
        "run's ensemble is not touched",
        named_errors=True,
    )
    check.add_argument("run", help="run folder (or its id under runs/)")
    check.add_argument(
        "--tighten",
        type=float,
        default=10.0,
        metavar="F",
        help="tightening factor (default 10)",
    )
    check.add_argument(
        "--samples",
        type=positive,
        default=None,
        metavar="M",
        help="samples re-solved spread evenly over the run, before those near a limit (default: "
        "enough to bound the unseen flips by a tenth of the narrowest interval, at least 64)",
    )

    verdict = sub.add_parser(
        "verdict",
        help="the requirements' verdict table; exit 0 all pass, 1 one fails, 4 one undecided",
        description="print every requirement's verdict with its bounds and units; exit 0 when "
        "every requirement passes, 1 when one fails, 4 when none fails but one is undecided (2: "
        "a bad run or a run without requirements)",
        named_errors=True,
    )
    verdict.add_argument("run", help="run folder (or its id under runs/)")

    rare = sub.add_parser(
        "rare",
        help="estimate a rare failure probability by subset simulation",
        description="estimate P(fail) of one requirement by subset simulation (Au & Beck "
        "2001) on the scene's kernels; writes a run folder with export/subset.csv",
        named_errors=True,
    )
    rare.add_argument("scene", metavar="SCENE.toml", help="scene file with [[requirement]]")
    rare.add_argument("--requirement", required=True, metavar="NAME", help="the requirement")
    rare.add_argument(
        "--per-level",
        type=positive,
        default=1000,
        metavar="N",
        help="samples per level, a multiple of 10 (default 1000)",
    )
    rare.add_argument("--seed", type=seed, metavar="S", help="override [sample] seed")
    rare.add_argument("--out", metavar="DIR", help="folder of run folders (default: runs)")
    rare.add_argument("--run-dir", metavar="PATH", help="exact run folder (must not exist)")

    add_confirm_parser(sub)
    add_cache_parser(sub)
    return parser


def add_confirm_parser(sub: Any) -> None:
    """``mcchain confirm RUN --requirement NAME``: a new run inside an allocated range."""
    confirm = sub.add_parser(
        "confirm",
        help="decide an allocated range on fresh samples: a new run of the scene with the "
        "range cut into its distribution",
        description="run the scene of RUN again with a fresh seed and one parameter's "
        "distribution cut to the range allocated for requirement NAME (or --box, or --range), "
        "and give that requirement's verdict there; exit 0 pass, 1 fail, 4 undecided",
        named_errors=True,
    )
    confirm.add_argument("run", help="run folder (or its id under runs/)")
    confirm.add_argument("--requirement", required=True, metavar="NAME", help="the requirement")
    confirm.add_argument(
        "--parameter", metavar="PATH", help="confirm this parameter's allocated range"
    )
    confirm.add_argument(
        "--box", action="store_true", help="confirm the box over all sampled parameters"
    )
    confirm.add_argument(
        "--range",
        action="append",
        default=[],
        metavar="PATH=LOW:HIGH",
        help="confirm this range (repeatable; an empty end is not cut)",
    )
    confirm.add_argument(
        "--samples",
        type=positive,
        metavar="N",
        help="samples of the new run (default: from the success-run figure, or what the rate "
        "seen inside the range needs to decide)",
    )
    confirm.add_argument("--seed", type=seed, metavar="S", help="seed (default: the run's + 1)")
    confirm.add_argument("--out", metavar="DIR", help="folder of run folders (default: runs)")
    confirm.add_argument("--run-dir", metavar="PATH", help="exact run folder (must not exist)")
    confirm.add_argument("--quiet", action="store_true", help="no progress bar")


def add_cache_parser(sub: Any) -> None:
    """``mcchain cache status | warm SCENE… | clear``: the compiled-code caches."""
    cache = sub.add_parser(
        "cache",
        help="what is compiled, where; compile scenes ahead; clear the caches",
        description="mcchain's compiled-code caches (MCCHAIN_CACHE_DIR, numba's cache of "
        "mcchain's kernels)",
    )
    action = cache.add_subparsers(
        dest="cache_action", metavar="{status,warm,clear}", required=True, parser_class=Parser
    )
    action.add_parser("status", help="what is compiled, where, sizes, versions and target")
    warm = action.add_parser(
        "warm",
        help="compile every kernel these scenes' runs call, now (for CI images and cluster "
        "nodes: their runs then compile nothing)",
    )
    warm.add_argument("scenes", nargs="+", metavar="SCENE.toml")
    action.add_parser("clear", help="remove all compiled code and cached designs")


def add_show_arguments(parser: argparse.ArgumentParser) -> None:
    """The ``mcchain show`` arguments.

    The viewer flags are those of ``rr.script_add_args`` (``--save``, ``--serve``,
    ``--connect``/``--url``, ``--stdout``, ``--headless``) plus ``--spawn`` (the default),
    which :func:`mcchain.viz.show.show` hands to ``rr.script_setup``; they are declared
    here rather than by ``rr.script_add_args`` so that parsing does not import rerun.
    """
    from mcchain.ensemble.queries import DEFAULT_LIMIT
    from mcchain.status import Status
    from mcchain.viz.playback import DEFAULT_MAGNIFY

    parser.add_argument("run", help="run folder")
    parser.add_argument("--samples", help="comma-separated global sample indices, e.g. 0,17")
    parser.add_argument(
        "--worst", metavar="VARIABLE:N", help="the N samples of largest peak |VARIABLE|"
    )
    parser.add_argument(
        "--status",
        metavar="FLAG[,FLAG]",
        help="samples carrying any of these status flags ("
        + ", ".join(["ok", *(f.meaning for f in Status)])
        + ")",
    )
    parser.add_argument(
        "--failed",
        metavar="NAME",
        help="samples failing requirement NAME, farthest beyond its limit first (--limit)",
    )
    parser.add_argument(
        "--limit",
        type=int,
        default=DEFAULT_LIMIT,
        help=f"most samples --status or --failed picks (default {DEFAULT_LIMIT})",
    )
    parser.add_argument(
        "--magnify",
        type=float,
        default=DEFAULT_MAGNIFY,
        help=f"draw clearance offsets this many times longer (default {DEFAULT_MAGNIFY:g})",
    )
    parser.add_argument(
        "--force-scale", type=float, default=None, help="force arrows, m per N (default: auto)"
    )
    sink = parser.add_mutually_exclusive_group()
    sink.add_argument("--save", metavar="FILE.rrd", help="save the recording to this file")
    sink.add_argument("--spawn", action="store_true", help="spawn a viewer (the default)")
    sink.add_argument("--serve", action="store_true", help="serve gRPC and a web viewer")
    sink.add_argument("--connect", action="store_true", help="connect to a running viewer")
    sink.add_argument("--stdout", action="store_true", help="write the recording to stdout")
    sink.add_argument("--headless", action="store_true", help="log nowhere (for timing)")
    parser.add_argument("--url", help="viewer URL for --connect")
    parser.add_argument(
        "--force", action="store_true", help="--save: overwrite the file if it exists"
    )


def resume_arguments(args: list[str]) -> list[str]:
    """The options of a ``mcchain run`` command line ``args`` that a resume takes too
    (:func:`mcchain.compiled.first_run.run_compiled`)."""
    parser = argparse.ArgumentParser(add_help=False)
    parser.add_argument("--threads")
    parser.add_argument("--quiet", action="store_true")
    known, _ = parser.parse_known_args(args)
    kept = [] if known.threads is None else ["--threads", known.threads]
    return kept + (["--quiet"] if known.quiet else [])
