"""``mcchain`` command line: a thin front end, and the one place that parses arguments.

Commands: ``run`` (:mod:`mcchain.execution`), ``validate``, ``runs`` (:mod:`mcchain.runs`),
``show`` (:func:`mcchain.viz.playback.show_run`), ``report``
(:func:`mcchain.viz.report.write_report`); the benchmarks are scripts in ``benchmarks/``.
A bad input (``SceneError``, ``RunError``, a bad
flag) prints one line ``mcchain: error: <message>`` on stderr and exits with 2, having
written nothing; usage errors of ``show`` and ``report`` name the command
(``mcchain show: ...``). A run that fails once started (a full disk, its folder removed,
``RunFailed``) prints one such line and exits with 1, keeping its finished chunks; a run
that completes with every sample failed prints its folder, then one such line with the
status counts, and exits with 3.

This module imports only the standard library at import time, and building the parser
does too (``mcchain runs`` must stay fast): ``show``'s arguments, whose help lists the
status flags, are added when ``show`` is parsed.
"""

from __future__ import annotations

import argparse
import atexit
import contextlib
import os
import sys
from collections.abc import Callable, Sequence
from typing import Any, NoReturn

from mcchain import __version__
from mcchain.errors import McchainError, RunFailed

EXIT_USAGE = 2
EXIT_FAILED = 1
EXIT_INTERRUPTED = 130
EXIT_ALL_FAILED = 3
"""``mcchain run``: the run completed, but every one of its samples failed."""

"""Commands that parse the rest of the command line themselves."""
NAMED_ERRORS = ("show", "report")
"""Commands whose usage errors start with ``mcchain <command>:``."""


class _UsageError(Exception):
    pass


class _Parser(argparse.ArgumentParser):
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
        raise _UsageError(f"{self.prog}: {message}" if self._named_errors else message)


def _fail(message: str, code: int = EXIT_USAGE) -> int:
    print(f"mcchain: error: {message}", file=sys.stderr)
    return code


def _positive(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {value}")
    return value


def _seed(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {value}")
    return value


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="mcchain",
        description=__doc__.splitlines()[0],
        epilog="Scene file format (every key, unit and default): docs/scenes.md",
    )
    parser.add_argument("--version", action="version", version=f"mcchain {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    run = sub.add_parser("run", help="run a scene into a new run folder, or resume a run")
    run.add_argument(
        "scene", nargs="?", metavar="SCENE.toml", help="scene file (format: docs/scenes.md)"
    )
    run.add_argument("--samples", type=_positive, metavar="N", help="override [sample] count")
    run.add_argument("--seed", type=_seed, metavar="S", help="override [sample] seed")
    run.add_argument(
        "--chunk-size", type=_positive, metavar="K", help="samples per chunk ([storage])"
    )
    run.add_argument("--out", metavar="DIR", help="folder of run folders (default: runs)")
    run.add_argument("--run-dir", metavar="PATH", help="exact run folder (must not exist)")
    run.add_argument(
        "--dask", metavar="ADDRESS|local", help="run chunks on a Dask cluster ('local' starts one)"
    )
    run.add_argument(
        "--threads",
        type=_positive,
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
        help="re-solve a subset of a run with a tighter integration and count flipped verdicts",
        description="re-solve a subset of a run's samples with rtol/atol (or dt) TIGHTEN times "
        "tighter; per requirement, how many verdicts flip and how far the outputs move "
        "(RUN/export/check.csv); the run's ensemble is not touched",
        named_errors=True,
    )
    check.add_argument("run", help="run folder (or its id under runs/)")
    check.add_argument(
        "--tighten", type=float, required=True, metavar="F", help="tightening factor (e.g. 10)"
    )
    check.add_argument(
        "--samples",
        type=_positive,
        default=64,
        metavar="M",
        help="samples re-solved, spread evenly over the run (default 64)",
    )

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
        type=_positive,
        default=1000,
        metavar="N",
        help="samples per level, a multiple of 10 (default 1000)",
    )
    rare.add_argument("--seed", type=_seed, metavar="S", help="override [sample] seed")
    rare.add_argument("--out", metavar="DIR", help="folder of run folders (default: runs)")
    rare.add_argument("--run-dir", metavar="PATH", help="exact run folder (must not exist)")

    add_cache_parser(sub)
    return parser


def add_cache_parser(sub: Any) -> None:
    """``mcchain cache status | warm SCENE… | clear``: the compiled-code caches."""
    cache = sub.add_parser(
        "cache",
        help="what is compiled, where; compile scenes ahead; clear the caches",
        description="mcchain's compiled-code caches (MCCHAIN_CACHE_DIR, numba's cache of "
        "mcchain's kernels)",
    )
    action = cache.add_subparsers(
        dest="cache_action", metavar="{status,warm,clear}", required=True, parser_class=_Parser
    )
    action.add_parser("status", help="what is compiled, where, sizes, versions and target")
    warm = action.add_parser(
        "warm",
        help="compile every kernel these scenes' runs call, now (for CI images and cluster "
        "nodes: their runs then compile nothing)",
    )
    warm.add_argument("scenes", nargs="+", metavar="SCENE.toml")
    action.add_parser("clear", help="remove all compiled code and cached designs")


def _cmd_cache(args: argparse.Namespace) -> int:
    from mcchain import caches

    if args.cache_action == "status":
        print("\n".join(caches.status_lines()))
    elif args.cache_action == "clear":
        print("\n".join(caches.clear()))
    else:
        from mcchain.compile_ahead import warm

        for scene in args.scenes:
            print(warm(scene))
    return 0


def add_show_arguments(parser: argparse.ArgumentParser) -> None:
    """The ``mcchain show`` arguments.

    The viewer flags are those of ``rr.script_add_args`` (``--save``, ``--serve``,
    ``--connect``/``--url``, ``--stdout``, ``--headless``) plus ``--spawn`` (the default),
    which :func:`mcchain.viz.playback.show` hands to ``rr.script_setup``; they are declared
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


# -- commands ----------------------------------------------------------------------------------


def _live_options(args: argparse.Namespace) -> Any:
    """``--rerun SAMPLES [--rerun-save FILE | --rerun-spawn]`` as ``viz.live.LiveOptions``
    (``None`` without ``--rerun``); raises ``RunError`` naming the flag."""
    from pathlib import Path

    from mcchain.errors import RunError
    from mcchain.viz.live import LiveOptions, parse_rerun_samples

    if args.rerun is None:
        for flag, value in (("--rerun-save", args.rerun_save), ("--rerun-spawn", args.rerun_spawn)):
            if value:
                raise RunError(f"{flag}: requires --rerun SAMPLES")
        return None
    if args.rerun_save is not None and args.rerun_spawn:
        raise RunError("--rerun-spawn: cannot be combined with --rerun-save (one sink)")
    if args.rerun_save is not None and not args.rerun_save.strip():
        raise RunError("--rerun-save: expected a file name")
    save = Path(args.rerun_save) if args.rerun_save is not None else None
    return LiveOptions(parse_rerun_samples(args.rerun), save=save, spawn=bool(args.rerun_spawn))


def _cmd_run(args: argparse.Namespace) -> int:
    from mcchain import execution, runs

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
            return _fail(f"--extend: cannot be combined with {', '.join(conflicting)}")
        if args.samples is None:
            return _fail("--extend: give the number of samples to add: --samples N")
        result = execution.extend_run(
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
            return _fail(f"--resume: cannot be combined with {', '.join(conflicting)}")
        result = execution.resume_run(
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
            return _fail("--remerge: only with --resume RUN")
        if args.scene is None:
            return _fail("run: a SCENE.toml (or --resume RUN) is required")
        if args.out is not None and args.run_dir is not None:
            return _fail("--run-dir: cannot be combined with --out")
        first_run = None
        if _may_interpret and args.dask is None:
            from mcchain.first_run import choose

            first_run = choose(args.scene, args.samples, args.seed)
        background_off = None
        if first_run is not None:
            from mcchain.user_config import background_compile_off

            background_off = background_compile_off()
            if args.no_background_compile:
                background_off = "--no-background-compile"
        result = execution.start_run(
            args.scene,
            samples=args.samples,
            seed=args.seed,
            chunk_size=args.chunk_size,
            out=args.out or runs.DEFAULT_OUT,
            run_dir=args.run_dir,
            dask=args.dask,
            threads=args.threads,
            argv=argv,
            progress=progress,
            rerun=live,
            first_run=first_run,
            background_off=background_off,
        )
    for line in result.summary():
        print(line)
    print(result.folder)
    if result.all_failed:
        sys.stdout.flush()  # the folder, then the error line
        samples = result.record["samples"]
        return _fail(
            f"every one of the {samples} samples failed ({result.counts_line()})", EXIT_ALL_FAILED
        )
    return 0


def _fmt(value: Any) -> str:
    import numpy as np

    arr = np.asarray(value, dtype=float).reshape(-1)
    text = ", ".join(f"{v:.6g}" for v in arr)
    return text if arr.size == 1 else f"[{text}]"


def _units(units: str) -> str:
    """CF units as ``validate`` prints them: a ``-1`` power after a slash (``rad s-1`` ->
    ``rad/s``)."""
    words = [w for w in units.split() if w != "1"]  # dimensionless: no unit
    num = [w for w in words if not w.endswith("-1")]
    den = [w[:-2] for w in words if w.endswith("-1")]
    return " ".join(num) + "".join(f"/{w}" for w in den)


def describe_model(model: Any, scene_name: str, nominal: Any = None) -> list[str]:
    """The lines ``mcchain validate`` prints: bodies, joints, drivers, rows, dof.

    Values are those of ``nominal`` (the scene without ``[sample]``) when given, else of the
    first sample; each sampled path is listed with its range over ``model``'s samples.
    """
    import numpy as np

    from mcchain.contact import LAW_NAMES, LINK, MODEL_NAMES
    from mcchain.model import DRIVER_HARMONIC, DRIVER_TABLE, GROUND, JointKind
    from mcchain.parameters import PARAMETERS

    def body(index: int) -> str:
        return "ground" if index == GROUND else str(model.body_names[index])

    values = model if nominal is None else nominal

    def show(kind: str, item: int, *keys: str) -> str:
        """``key value units`` of each key of one item (the first sample's values)."""
        rows = [PARAMETERS[kind, key] for key in keys]
        return ", ".join(
            f"{row.key.split('.')[-1]} {_fmt(row.read(values, item))} {_units(row.units)}".rstrip()
            for row in rows
        )

    lines = [
        f"scene {scene_name}: {model.nbody} bodies, {model.njoint} joints, "
        f"{model.ndriver} drivers, {model.nsample} samples"
    ]
    lines.append("bodies:")
    for i, name in enumerate(model.body_names):
        lines.append(f"  {name}: {show('body', i, 'mass', 'inertia', 'position', 'angle')}")
    lines.append("joints:")
    for j, name in enumerate(model.joint_names):
        kind = JointKind(int(model.joint_kind[j]))
        row = int(model.joint_row[j])
        rows = f"row {row}" if kind.rows == 1 else f"rows {row}-{row + kind.rows - 1}"
        what = (
            show("joint", j, "clearance")
            if kind == JointKind.CLEARANCE
            else f"prismatic, {show('joint', j, 'axis', 'relative_angle')}"
            if kind == JointKind.PRISMATIC
            else "ideal"
        )
        law = ""
        if int(model.joint_model[j]) != LINK:  # the contact law of [simulate]
            law = (
                f", model {MODEL_NAMES[int(model.joint_model[j])]}: "
                f"{LAW_NAMES[int(model.joint_contact_law[j])]} law, "
                + show("joint", j, "contact.stiffness", "contact.exponent", "contact.restitution")
            )
        lines.append(
            f"  {name}: {body(int(model.joint_body_a[j]))} (bearing) - "
            f"{body(int(model.joint_body_b[j]))} (journal), {what}, {rows}{law}"
        )
    if model.ndriver:
        lines.append("drivers:")
        for k, name in enumerate(model.driver_names):
            slider = int(model.driver_joint[k]) >= 0
            driver_law = int(model.driver_law[k])
            start, rate = ("displacement0", "speed") if slider else ("angle0", "omega")
            what = f"joint {name} along its axis, " if slider else ""
            if driver_law == DRIVER_TABLE:
                n = int(model.driver_table_size[k])
                knots = model.driver_table_knots[k, :n]
                what += f"table of {n} points over [{knots[0]:g}, {knots[-1]:g}] s, "
                shown = show("driver", k, start) + " (from the table)"
            else:
                shown = show("driver", k, rate, start)
                if driver_law == DRIVER_HARMONIC:
                    swing = show("driver", k, "amplitude", "frequency", "phase")
                    shown += ", " + (swing.replace(" rad,", " m,", 1) if slider else swing)
            row = int(model.driver_row[k])
            lines.append(f"  {name}: {what}{shown}, row {row}")
    if model.param_paths:
        lines.append("sampled (range over the samples):")
        params = np.asarray(model.parameters, dtype=float)
        for k, path in enumerate(model.param_paths):
            lo, hi = np.nanmin(params[:, k]), np.nanmax(params[:, k])
            lines.append(f"  {path}: {_fmt(lo)} … {_fmt(hi)}")
    lines.append(f"coordinates: {model.ndof}")
    lines.append(f"constraint rows: {model.ncon}")
    lines.append(f"degrees of freedom: {model.nmode}")
    return lines


def describe_initial_state(model: Any, assembled: Any) -> list[str]:
    """The lines ``mcchain validate`` prints about the assembled state at t = 0 (sample 0 of
    ``model``): each body's pose and velocity; each clearance joint's d, |d| − c, the model
    it starts its time history in and the force that model gives at t = 0."""
    import numpy as np

    from mcchain.contact import START_LINK, START_SEATED
    from mcchain.kernels.joints import joint_vectors
    from mcchain.model import JointKind
    from mcchain.solvers.simulate import start_modes
    from mcchain.solvers.statics import start_multipliers

    if int(assembled.status[0]) != 0:
        return ["initial state: cannot be assembled"]
    q, v = assembled.q[0], assembled.v[0]
    lines = ["initial state at t = 0 (assembled):"]
    for b, name in enumerate(model.body_names):
        x, y, th = q[3 * b : 3 * b + 3]
        vx, vy, w = v[3 * b : 3 * b + 3]
        lines.append(
            f"  {name}: position [{_fmt(x)}, {_fmt(y)}] m, angle {_fmt(th)} rad, "
            f"velocity [{_fmt(vx)}, {_fmt(vy)}] m/s, angular velocity {_fmt(w)} rad/s"
        )
    clearance = np.flatnonzero(model.joint_kind == JointKind.CLEARANCE)
    if clearance.size:
        modes = start_modes(model, q[np.newaxis])[0]
        lam = start_multipliers(model, q, v)  # every clearance joint on the link
        law = (np.asarray(model.joint_model) != 0) & (modes != START_LINK)
        # model auto on the wall starts on the link only where the link pushes
        law |= (np.asarray(model.joint_model) != 0) & (lam[model.joint_row] <= 0.0)
        if law.any():
            lam = start_multipliers(model, q, v, law=law)
        km = model.kernel_model()
        for k in clearance:
            dx, dy = joint_vectors(km, 0, q, int(k))[4:]
            gap = float(np.hypot(dx, dy) - model.joint_clearance[0, k])
            force = float(lam[int(model.joint_row[k])])
            if not law[k]:
                start = "the link" + (" (model auto)" if model.joint_model[k] != 0 else "")
                state = "holds" if force > 0 else "lost at the start: the journal is pulled off"
                text = f"link force {_fmt(force)} N: contact {state}"
            else:
                where = (
                    "seated on the wall"
                    if modes[k] in (START_SEATED, START_LINK)
                    else "pressed in"
                    if gap > 0
                    else "free"
                )
                start = f"the contact law, {where}"
                text = f"contact force {_fmt(force)} N (K max(|d| - c, 0)^m, undamped)"
            lines.append(
                f"  {model.joint_names[k]}: |d| {_fmt(float(np.hypot(dx, dy)))} m at "
                f"{_fmt(float(np.arctan2(dy, dx)))} rad (eccentricity), |d| - c {_fmt(gap)} m; "
                f"starts on {start}: {text}"
            )
    return lines


VALIDATE_COMPILED = "MCCHAIN_VALIDATE_COMPILED"
"""``1``: ``mcchain validate`` checks with the compiled kernels (its fallback process)."""

_may_interpret = False
"""Set by :func:`console_main`: this process only validates or runs one scene, so its
kernels may run interpreted (``validate``: :func:`_interpret_for`; ``run``:
:mod:`mcchain.first_run`)."""


def _interpret_for(scene_path: Any) -> bool:
    """Whether ``validate`` runs the kernels interpreted: only in a process that does
    nothing else (:func:`console_main`), for a scene of at most
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
    from mcchain.job import default_loader, written_state

    scene, model = default_loader(scene_path, None, None)
    name = getattr(getattr(scene, "scene", None), "name", scene_path)
    written, assembled = written_state(scene)
    nominal = written if getattr(scene, "sample", None) is not None else None
    lines = [*describe_model(model, name, nominal), *describe_initial_state(written, assembled)]
    sim = getattr(scene, "simulate", None)
    if sim is not None:
        from mcchain.solvers.simulate import choose_kernels

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
    from mcchain.resources import estimate_disk

    estimate = estimate_disk(scene, model, model.nsample, scene.storage.chunk_size)
    assert estimate is not None
    return estimate.line()


def _cmd_runs(args: argparse.Namespace) -> int:
    from mcchain.runs import format_runs, list_runs

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
    from mcchain.viz.playback import show_run

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
    from mcchain.viz.report import write_report

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
            return _fail("--out: not with --requirements (the files go to RUN/export/)")
        for path in export_requirements(args.run):
            print(path)
        if not args.csv:
            return 0
    if not args.csv:
        return _fail("export: give the format: --csv or --requirements")
    print(export_run(args.run, args.out))
    return 0


def _cmd_check(args: argparse.Namespace) -> int:
    from mcchain.decision.check import check_run

    result = check_run(args.run, args.tighten, args.samples)
    for line in result.lines():
        print(line)
    print(result.csv)
    return 0


def _cmd_rare(args: argparse.Namespace) -> int:
    from mcchain.decision.rare import rare_run

    if args.out is not None and args.run_dir is not None:
        return _fail("--run-dir: cannot be combined with --out")
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


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``mcchain`` console script; returns the exit code."""
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser()
    try:
        args, extra = parser.parse_known_args(argv)
    except _UsageError as exc:
        return _fail(str(exc))
    command = args.command
    if extra:
        message = f"unrecognized arguments: {' '.join(extra)}"
        return _fail(f"mcchain {command}: {message}" if command in NAMED_ERRORS else message)
    try:
        handler = {
            "run": _cmd_run,
            "validate": _cmd_validate,
            "runs": _cmd_runs,
            "show": _cmd_show,
            "report": _cmd_report,
            "export": _cmd_export,
            "check": _cmd_check,
            "rare": _cmd_rare,
            "cache": _cmd_cache,
        }[command]
        return handler(args)
    except RunFailed as exc:
        return _fail(str(exc).splitlines()[0], EXIT_FAILED)
    except McchainError as exc:
        return _fail(str(exc).splitlines()[0] if str(exc) else type(exc).__name__)
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

    ``validate`` and ``run`` may run their kernels interpreted here (:func:`_interpret_for`,
    :mod:`mcchain.first_run`), never when :func:`main` is called in a process that may go
    on to solve.
    """
    global _may_interpret
    _may_interpret = sys.argv[1:2] in (["validate"], ["run"])
    code = main()
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(OSError, ValueError):  # a closed pipe: nothing to flush to
            stream.flush()
    os._exit(code)


if __name__ == "__main__":
    console_main()
