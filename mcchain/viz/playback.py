"""Replay samples of an ensemble in the rerun viewer (``mcchain show``) and stream them live.

``mcchain show RUN --samples 0,17 [--save FILE.rrd | --spawn | --serve]`` draws each chosen
sample of a run (DESIGN §6). Samples may also be picked by a criterion:
``--worst VARIABLE:N`` takes the N samples with the largest peak ``|VARIABLE|`` (e.g.
``--worst contact_force:3``) and ``--status contact_lost`` those whose status carries a flag
(names of :attr:`mcchain.status.Status.meaning`, plus ``ok``; with both, the worst N of the
samples with that status).

Entities (``{i}`` is the global sample index, names are escaped entity-path parts):

=======================================  ==============================================
``sample/{i}/info``                      TextDocument (static): parameters, status
``sample/{i}/mechanism/ground``          Points2D (static): bearings fixed to the ground
``sample/{i}/mechanism/bodies``          LineStrips2D: each body through its points
``sample/{i}/mechanism/centres``         Points2D: centres of mass
``sample/{i}/mechanism/joints``          Points2D: bearing centres
``sample/{i}/mechanism/forces``          Arrows2D: joint force on body b, scaled
``sample/{i}/mechanism/clearance/...``   ``journal`` Points2D, ``offset`` Arrows2D and
                                         ``bearing`` LineStrips2D (circle of radius c),
                                         all magnified (see ``--magnify``)
``sample/{i}/joint_force/{joint}``       Scalars [x, y] (N)
``sample/{i}/contact_force/{joint}``     Scalars λ of clearance joints (N)
``sample/{i}/driver_torque/{driver}``    Scalars (N m)
``sample/{i}/energy``                    Scalars (J)
``sample/{i}/constraint_error``          Scalars max |Φ|
=======================================  ==============================================

Everything that changes goes through ``send_columns`` on the ``time`` timeline (a duration,
seconds); styling and the ground are logged once as static. A run without ``[simulate]``
shows its equilibrium (``q_eq``, ``joint_force_eq``) as one frame at t = 0.

Drawing conventions:

* rerun's 2D views put +y *down* (image convention), so the mechanism view draws world y
  negated: gravity (−y) points down on the screen. The scalar plots carry the true values.
* The journal offset of a clearance joint is as small as the clearance (0.1 mm); it is drawn
  ``--magnify`` times longer (default :data:`DEFAULT_MAGNIFY` = 100, so 0.1 mm shows as
  1 cm). Bodies are drawn where they are.
* Force arrows are ``--force-scale`` m per N; by default the largest force among the samples
  shown is drawn :data:`FORCE_ARROW_FRACTION` of the mechanism's size.
"""

from __future__ import annotations

import argparse
import logging
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from mcchain.errors import RunError
from mcchain.model import JOINT_CLEARANCE, Model
from mcchain.status import Status
from mcchain.viz import geometry

if TYPE_CHECKING:
    import rerun as rr
    import rerun.blueprint as rrb
    import xarray as xr

log = logging.getLogger(__name__)

APPLICATION_ID = "mcchain"
DEFAULT_MAGNIFY = 100.0
"""Default magnification of clearance offsets: 0.1 mm is drawn as 1 cm."""
FORCE_ARROW_FRACTION = 0.3
"""Default force scale: the largest force shown is drawn this fraction of the mechanism size."""
DEFAULT_LIMIT = 16
"""Most samples ``--status`` alone picks (a recording of thousands of samples is unusable)."""
PEAK_BLOCK = 512
"""Samples read at once when ranking ``--worst`` (bounds memory on long histories)."""

BODY_COLORS = np.array(
    [
        [31, 119, 180],
        [255, 127, 14],
        [44, 160, 44],
        [214, 39, 40],
        [148, 103, 189],
        [140, 86, 75],
        [227, 119, 194],
        [127, 127, 127],
        [188, 189, 34],
        [23, 190, 207],
    ],
    dtype=np.uint8,
)
JOINT_COLOR = [20, 20, 20]
GROUND_COLOR = [90, 90, 90]
FORCE_COLOR = [200, 30, 30]
CLEARANCE_COLOR = [0, 150, 136]

_RERUN_FLAGS = ("headless", "connect", "serve", "url", "save", "stdout")
"""Attributes ``rr.script_setup`` reads from the parsed arguments."""


# -- arguments ---------------------------------------------------------------------------------
def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the ``mcchain show`` arguments to ``parser``.

    The viewer flags are those of ``rr.script_add_args`` (``--save``, ``--serve``,
    ``--connect``/``--url``, ``--stdout``, ``--headless``) plus ``--spawn`` (the default), so
    that ``rr.script_setup``/``script_teardown`` read them; they are declared here rather than
    by ``rr.script_add_args`` so that building the CLI parser does not import rerun.
    """
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
        "--limit",
        type=int,
        default=DEFAULT_LIMIT,
        help=f"most samples --status alone picks (default {DEFAULT_LIMIT})",
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


def parse_samples(text: str | None) -> list[int]:
    """``"0,17"`` -> ``[0, 17]``; raises :class:`RunError` naming ``--samples``."""
    if not text:
        return []
    try:
        values = [int(part) for part in text.split(",") if part.strip()]
    except ValueError:
        raise RunError(f"--samples: expected comma-separated integers, got {text!r}") from None
    if any(v < 0 for v in values):
        raise RunError(f"--samples: sample indices are >= 0, got {text!r}")
    return list(dict.fromkeys(values))


def parse_worst(text: str) -> tuple[str, int]:
    """``"contact_force:3"`` -> ``("contact_force", 3)``; raises :class:`RunError`."""
    name, sep, count = text.rpartition(":")
    if not sep or not name:
        raise RunError(f"--worst: expected VARIABLE:N, got {text!r}")
    try:
        n = int(count)
    except ValueError:
        raise RunError(f"--worst: N must be an integer, got {count!r}") from None
    if n < 1:
        raise RunError(f"--worst: N must be >= 1, got {n}")
    return name, n


# -- sample selection --------------------------------------------------------------------------
def _sample_ids(ds: xr.Dataset) -> np.ndarray:
    if "sample" in ds.coords:
        return np.asarray(ds["sample"].values, dtype=np.int64)
    return np.arange(ds.sizes["sample"], dtype=np.int64)


def peak_abs(ds: xr.Dataset, variable: str, block: int = PEAK_BLOCK) -> np.ndarray:
    """Peak ``|variable|`` of every sample over all its other axes (NaN if all NaN).

    Reads ``block`` samples at a time, so a lazy ensemble is never loaded whole.
    """
    if variable not in ds.data_vars or "sample" not in ds[variable].dims:
        choices = sorted(
            str(name)
            for name, v in ds.data_vars.items()
            if "sample" in v.dims and v.dtype.kind == "f"
        )
        raise RunError(
            f"--worst: no per-sample variable {variable!r} in the run "
            f"(choose from {', '.join(choices)})"
        )
    da = ds[variable].transpose("sample", ...)
    n = ds.sizes["sample"]
    peak = np.full(n, np.nan)
    for start in range(0, n, block):
        values = np.abs(np.asarray(da.isel(sample=slice(start, start + block)).values, float))
        flat = values.reshape(values.shape[0], -1)
        finite = np.isfinite(flat)
        has = finite.any(axis=1)
        peak_block = np.where(finite, flat, -np.inf).max(axis=1, initial=-np.inf)
        peak[start : start + len(flat)] = np.where(has, peak_block, np.nan)
    return peak


def _status_mask(ds: xr.Dataset, names: str) -> np.ndarray:
    known = {flag.meaning: int(flag.value) for flag in Status}
    status = np.asarray(ds["status"].values, dtype=np.int64)
    mask = np.zeros(status.shape, dtype=bool)
    for name in (part.strip() for part in names.split(",") if part.strip()):
        if name == "ok":
            mask |= status == 0
        elif name in known:
            mask |= (status & known[name]) != 0
        else:
            raise RunError(f"--status: unknown flag {name!r} (choose from ok, {', '.join(known)})")
    return mask


def select_samples(
    ds: xr.Dataset,
    samples: Sequence[int] = (),
    worst: str | None = None,
    status: str | None = None,
    limit: int = DEFAULT_LIMIT,
) -> list[int]:
    """Global sample indices to show, in order: ``samples`` first, then those the criteria pick.

    ``status`` (comma-separated flag names) filters the candidates; ``worst``
    (``VARIABLE:N``) takes the N candidates with the largest peak ``|VARIABLE|`` (samples with
    no finite value are never "worst"); ``status`` alone takes the first ``limit``. With no
    argument at all: the first sample.
    """
    ids = _sample_ids(ds)
    known = set(ids.tolist())
    chosen = list(dict.fromkeys(int(s) for s in samples))
    missing = [s for s in chosen if s not in known]
    if missing:
        raise RunError(
            f"--samples: {missing[0]} is not a sample of the run "
            f"({len(ids)} samples, {ids.min()}..{ids.max()})"
        )
    picked: list[int] = []
    if worst is not None or status is not None:
        candidates = np.ones(len(ids), dtype=bool)
        if status is not None:
            candidates &= _status_mask(ds, status)
        if worst is not None:
            variable, n = parse_worst(worst)
            peak = peak_abs(ds, variable)
            candidates &= np.isfinite(peak)
            order = np.argsort(-np.where(candidates, peak, -np.inf), kind="stable")
            picked = [int(ids[i]) for i in order[: min(n, int(candidates.sum()))]]
        else:
            where = np.flatnonzero(candidates)
            if len(where) > limit:
                log.info(
                    "--status %s matches %d samples; showing the first %d (--limit)",
                    status,
                    len(where),
                    limit,
                )
            picked = [int(ids[i]) for i in where[:limit]]
        if not picked and not chosen:
            raise RunError(
                f"no sample matches {' '.join(filter(None, [worst, status]))!s} in the run"
            )
    elif not chosen:
        chosen = [int(ids[0])]
    return list(dict.fromkeys(chosen + picked))


# -- one sample as arrays ----------------------------------------------------------------------
@dataclass(frozen=True)
class _Track:
    """The arrays that draw one sample (time first)."""

    time: np.ndarray
    q: np.ndarray
    joint_force: np.ndarray
    contact_force: np.ndarray | None
    driver_torque: np.ndarray | None
    energy: np.ndarray | None
    constraint_error: np.ndarray | None


def _values(ds: xr.Dataset, name: str, pos: int, *dims: str) -> np.ndarray | None:
    if name not in ds.data_vars:
        return None
    da = ds[name].isel(sample=pos)
    return np.asarray(da.transpose(*dims).values, dtype=np.float64)


def _track(ds: xr.Dataset, pos: int) -> _Track:
    if "q" in ds.data_vars:
        time = np.asarray(ds["time"].values, dtype=np.float64)
        q = _values(ds, "q", pos, "time", "body", "dof")
        jf = _values(ds, "joint_force", pos, "time", "joint", "xy")
        assert q is not None
        if jf is None:
            jf = np.full((len(time), ds.sizes.get("joint", 0), 2), np.nan)
        return _Track(
            time,
            q,
            jf,
            _values(ds, "contact_force", pos, "time", "joint"),
            _values(ds, "driver_torque", pos, "time", "driver"),
            _values(ds, "energy", pos, "time"),
            _values(ds, "constraint_error", pos, "time"),
        )
    if "q_eq" not in ds.data_vars:
        raise RunError("show: the run has neither a time history (q) nor an equilibrium (q_eq)")
    q = _values(ds, "q_eq", pos, "body", "dof")
    jf = _values(ds, "joint_force_eq", pos, "joint", "xy")
    assert q is not None
    if jf is None:
        jf = np.full((ds.sizes.get("joint", 0), 2), np.nan)
    return _Track(np.zeros(1), q[None], jf[None], None, None, None, None)


def _positions(ds: xr.Dataset, samples: Sequence[int]) -> list[int]:
    ids = _sample_ids(ds)
    where = {int(s): i for i, s in enumerate(ids)}
    missing = [s for s in samples if int(s) not in where]
    if missing:
        raise RunError(f"sample {missing[0]} is not in the dataset")
    return [where[int(s)] for s in samples]


def _flip(xy: np.ndarray) -> np.ndarray:
    """World (y up) to rerun 2D view coordinates (y down)."""
    out = np.array(xy, dtype=np.float64, copy=True)
    out[..., 1] *= -1.0
    return out


def _part(name: str) -> str:
    import rerun as rr

    return str(rr.escape_entity_path_part(name))


def default_force_scale(
    ds: xr.Dataset,
    model: Model,
    samples: Sequence[int],
    fraction: float = FORCE_ARROW_FRACTION,
    model_offset: int = 0,
) -> float:
    """m per N such that the largest joint force of ``samples`` is ``fraction`` of the
    mechanism size (1 if there is no finite non-zero force)."""
    fmax = 0.0
    for pos in _positions(ds, samples):
        jf = _track(ds, pos).joint_force
        mag = np.hypot(jf[..., 0], jf[..., 1])
        if np.isfinite(mag).any():
            fmax = max(fmax, float(np.nanmax(mag)))
    length = geometry.characteristic_length(model, int(samples[0]) - model_offset)
    return fraction * length / fmax if fmax > 0.0 else 1.0


# -- logging -----------------------------------------------------------------------------------
def _info_markdown(ds: xr.Dataset, model: Model, sample: int, pos: int) -> str:
    lines = [f"# sample {sample}", ""]
    if "parameters" in ds.data_vars and ds.sizes.get("param", 0):
        values = np.asarray(ds["parameters"].isel(sample=pos).values, dtype=np.float64)
        paths = [str(p) for p in ds["param"].values]
        lines += ["| parameter | value |", "| --- | --- |"]
        lines += [f"| `{p}` | {v:.6g} |" for p, v in zip(paths, values, strict=True)]
        lines.append("")
    if "status" in ds.data_vars:
        bits = int(ds["status"].isel(sample=pos).values)
        flags = [f.meaning for f in Status if bits & f.value]
        lines.append(f"status: {', '.join(flags) if flags else 'ok'}")
        lines += [f"- {msg}" for msg in Status.describe(bits)]
    for name in ("contact_lost_time", "diverged_time", "singular_time"):
        if name in ds.data_vars:
            t = float(ds[name].isel(sample=pos).values)
            if np.isfinite(t):
                lines.append(f"- {name}: {t:.6g} s")
    if "omega" in ds.data_vars:
        omega = np.asarray(ds["omega"].isel(sample=pos).values, dtype=np.float64)
        lines.append("")
        lines.append("ω (rad/s): " + ", ".join(f"{w:.6g}" for w in omega))
    return "\n".join(lines)


def log_samples(
    dataset: xr.Dataset,
    model: Model,
    samples: Sequence[int],
    recording: rr.RecordingStream | None = None,
    *,
    magnify: float = DEFAULT_MAGNIFY,
    force_scale: float | None = None,
    model_offset: int = 0,
) -> None:
    """Log ``samples`` (global indices) of ``dataset`` to ``recording`` (see the module doc).

    Args:
        dataset: an ensemble (DESIGN §5 variables) or the chunk of it being computed; only
            the variables present are logged.
        model: a model whose row ``s - model_offset`` is global sample ``s`` (the whole
            run's model with offset 0, or ``model.select(start, stop)`` with offset
            ``start``); it gives each sample's geometry (attachment points, clearances).
        samples: global sample indices (values of ``dataset.sample``).
        recording: where to log; ``None``: the current rerun recording.
        magnify: clearance offsets are drawn this many times longer.
        force_scale: force arrows, m per N; ``None``: :func:`default_force_scale` over these
            samples (pass a fixed value when logging chunk by chunk, so arrows compare).
        model_offset: global index of the model's first row.
    """
    import rerun as rr

    if not samples:
        return
    positions = _positions(dataset, samples)
    if force_scale is None:
        force_scale = default_force_scale(dataset, model, samples, model_offset=model_offset)
    for sample, pos in zip(samples, positions, strict=True):
        row = int(sample) - model_offset
        _log_one(dataset, model, int(sample), pos, row, recording, rr, magnify, force_scale)


def _log_one(
    ds: xr.Dataset,
    model: Model,
    sample: int,
    pos: int,
    row: int,
    rec: rr.RecordingStream | None,
    rr: Any,
    magnify: float,
    force_scale: float,
) -> None:
    root = f"sample/{sample}"
    mech = f"{root}/mechanism"
    track = _track(ds, pos)
    nt = len(track.time)
    times = [rr.TimeColumn("time", duration=track.time)]
    clearance = np.flatnonzero(np.asarray(model.joint_kind) == JOINT_CLEARANCE)

    # static: info, ground, styling ----------------------------------------------------------
    rr.log(
        f"{root}/info",
        rr.TextDocument(_info_markdown(ds, model, sample, pos), media_type="text/markdown"),
        static=True,
        recording=rec,
    )
    ground = [k for k in range(model.njoint) if model.joint_body_a[k] == geometry.GROUND]
    if ground:
        jpa = geometry._at(model.joint_point_a, row)
        rr.log(
            f"{mech}/ground",
            rr.Points2D(
                _flip(jpa[ground]),
                colors=GROUND_COLOR,
                radii=-6.0,
                labels=[f"{model.joint_names[k]} (ground)" for k in ground],
            ),
            static=True,
            recording=rec,
        )

    # bodies ---------------------------------------------------------------------------------
    outlines = geometry.body_outlines(model, row)
    world = [[geometry.to_world(strip, track.q[:, o.body]) for strip in o.strips] for o in outlines]
    per_frame = [strip for strips in world for strip in strips]
    colors = [BODY_COLORS[o.body % len(BODY_COLORS)] for o in outlines for _ in o.strips]
    labels = [o.name for o in outlines for _ in o.strips]
    if per_frame:
        rr.log(
            f"{mech}/bodies",
            rr.LineStrips2D.from_fields(colors=colors, labels=labels, radii=-2.5),
            static=True,
            recording=rec,
        )
        flat = [_flip(strip[t]) for t in range(nt) for strip in per_frame]
        rr.send_columns(
            f"{mech}/bodies",
            indexes=times,
            columns=rr.LineStrips2D.columns(strips=flat).partition([len(per_frame)] * nt),
            recording=rec,
        )
        centres = _flip(track.q[:, :, :2])
        rr.log(
            f"{mech}/centres",
            rr.Points2D.from_fields(
                colors=BODY_COLORS[np.arange(model.nbody) % len(BODY_COLORS)], radii=-4.0
            ),
            static=True,
            recording=rec,
        )
        rr.send_columns(
            f"{mech}/centres",
            indexes=times,
            columns=rr.Points2D.columns(positions=centres.reshape(-1, 2)).partition(
                [model.nbody] * nt
            ),
            recording=rec,
        )

    # joints, forces, clearances --------------------------------------------------------------
    if model.njoint:
        jt = geometry.joint_track(model, row, track.q, magnify)
        rr.log(
            f"{mech}/joints",
            rr.Points2D.from_fields(colors=JOINT_COLOR, radii=-4.0, labels=list(model.joint_names)),
            static=True,
            recording=rec,
        )
        rr.send_columns(
            f"{mech}/joints",
            indexes=times,
            columns=rr.Points2D.columns(positions=_flip(jt.bearing).reshape(-1, 2)).partition(
                [model.njoint] * nt
            ),
            recording=rec,
        )
        rr.log(
            f"{mech}/forces",
            rr.Arrows2D.from_fields(colors=FORCE_COLOR, radii=-2.0),
            static=True,
            recording=rec,
        )
        vectors = np.nan_to_num(track.joint_force * force_scale)
        rr.send_columns(
            f"{mech}/forces",
            indexes=times,
            columns=rr.Arrows2D.columns(
                origins=_flip(jt.drawn).reshape(-1, 2), vectors=_flip(vectors).reshape(-1, 2)
            ).partition([model.njoint] * nt),
            recording=rec,
        )
        if len(clearance):
            nc = len(clearance)
            for name, archetype in (
                ("journal", rr.Points2D.from_fields(colors=CLEARANCE_COLOR, radii=-4.0)),
                ("offset", rr.Arrows2D.from_fields(colors=CLEARANCE_COLOR, radii=-1.5)),
                ("bearing", rr.LineStrips2D.from_fields(colors=CLEARANCE_COLOR, radii=-1.0)),
            ):
                rr.log(f"{mech}/clearance/{name}", archetype, static=True, recording=rec)
            drawn = _flip(jt.drawn[:, clearance])
            bearing = _flip(jt.bearing[:, clearance])
            rr.send_columns(
                f"{mech}/clearance/journal",
                indexes=times,
                columns=rr.Points2D.columns(positions=drawn.reshape(-1, 2)).partition([nc] * nt),
                recording=rec,
            )
            rr.send_columns(
                f"{mech}/clearance/offset",
                indexes=times,
                columns=rr.Arrows2D.columns(
                    origins=bearing.reshape(-1, 2), vectors=(drawn - bearing).reshape(-1, 2)
                ).partition([nc] * nt),
                recording=rec,
            )
            rings = [
                geometry.circles(jt.bearing[:, k], float(jt.circle_radius[k])) for k in clearance
            ]
            rr.send_columns(
                f"{mech}/clearance/bearing",
                indexes=times,
                columns=rr.LineStrips2D.columns(
                    strips=[_flip(ring[t]) for t in range(nt) for ring in rings]
                ).partition([nc] * nt),
                recording=rec,
            )

    # scalar plots ---------------------------------------------------------------------------
    def scalars(path: str, values: np.ndarray, names: list[str] | None = None) -> None:
        if names is not None:
            rr.log(path, rr.SeriesLines(names=names), static=True, recording=rec)
        columns = rr.Scalars.columns(scalars=values.reshape(nt, -1).reshape(-1))
        width = values.reshape(nt, -1).shape[1]
        rr.send_columns(path, indexes=times, columns=columns.partition([width] * nt), recording=rec)

    for k, name in enumerate(model.joint_names):
        scalars(f"{root}/joint_force/{_part(name)}", track.joint_force[:, k], ["x", "y"])
    if track.contact_force is not None:
        for c in clearance:
            scalars(
                f"{root}/contact_force/{_part(model.joint_names[c])}",
                track.contact_force[:, c],
                [f"λ {model.joint_names[c]}"],
            )
    if track.driver_torque is not None:
        for k, name in enumerate(model.driver_names):
            scalars(f"{root}/driver_torque/{_part(name)}", track.driver_torque[:, k], [name])
    if track.energy is not None:
        scalars(f"{root}/energy", track.energy, ["energy"])
    if track.constraint_error is not None:
        scalars(f"{root}/constraint_error", track.constraint_error, ["max |Φ|"])


# -- blueprint and recording -------------------------------------------------------------------
def view_bounds(
    ds: xr.Dataset,
    model: Model,
    samples: Sequence[int],
    magnify: float = DEFAULT_MAGNIFY,
    model_offset: int = 0,
) -> tuple[list[float], list[float]]:
    """x and y ranges (view coordinates, y down) that hold every drawn point of ``samples``."""
    lo, hi = np.full(2, np.inf), np.full(2, -np.inf)
    for sample, pos in zip(samples, _positions(ds, samples), strict=True):
        row = int(sample) - model_offset
        track = _track(ds, pos)
        pts = [track.q[:, :, :2].reshape(-1, 2)]
        for o in geometry.body_outlines(model, row):
            for strip in o.strips:
                pts.append(geometry.to_world(strip, track.q[:, o.body]).reshape(-1, 2))
        if model.njoint:
            jt = geometry.joint_track(model, row, track.q, magnify)
            pts += [jt.bearing.reshape(-1, 2), jt.drawn.reshape(-1, 2)]
        allpts = _flip(np.concatenate(pts))
        allpts = allpts[np.isfinite(allpts).all(axis=1)]
        if len(allpts):
            lo, hi = np.minimum(lo, allpts.min(axis=0)), np.maximum(hi, allpts.max(axis=0))
    if not np.isfinite(lo).all():
        return [-1.0, 1.0], [-1.0, 1.0]
    margin = 0.15 * max(float((hi - lo).max()), 1e-6)
    return [lo[0] - margin, hi[0] + margin], [lo[1] - margin, hi[1] + margin]


def make_blueprint(
    ds: xr.Dataset,
    model: Model,
    samples: Sequence[int],
    magnify: float = DEFAULT_MAGNIFY,
    model_offset: int = 0,
) -> rrb.Blueprint:
    """The default layout: mechanism views (one per sample) beside the plots.

    ``samples`` not (yet) in ``ds`` get their views too (live streaming); the view bounds
    cover the drawn points of those that are.
    """
    import rerun.blueprint as rrb

    present = set(_sample_ids(ds).tolist())
    x_range, y_range = view_bounds(
        ds, model, [s for s in samples if s in present], magnify, model_offset
    )
    bounds = rrb.VisualBounds2D(x_range=x_range, y_range=y_range)
    mechanisms = [
        rrb.Spatial2DView(origin=f"/sample/{s}/mechanism", name=f"sample {s}", visual_bounds=bounds)
        for s in samples
    ]
    infos = [rrb.TextDocumentView(origin=f"/sample/{s}/info", name=f"sample {s}") for s in samples]

    def series(name: str, what: str) -> rrb.TimeSeriesView:
        return rrb.TimeSeriesView(
            origin="/", name=name, contents=[f"/sample/{s}/{what}" for s in samples]
        )

    plots = [series("joint forces (N)", "joint_force/**")]
    if "contact_force" in ds.data_vars and model.has_clearance:
        plots.append(series("contact force λ (N)", "contact_force/**"))
    if "driver_torque" in ds.data_vars and model.ndriver:
        plots.append(series("driver torque (N m)", "driver_torque/**"))
    if "energy" in ds.data_vars:
        plots.append(series("energy (J)", "energy"))
    if "constraint_error" in ds.data_vars:
        plots.append(series("constraint error max |Φ|", "constraint_error"))
    left = rrb.Vertical(
        rrb.Grid(*mechanisms) if len(mechanisms) > 1 else mechanisms[0],
        rrb.Tabs(*infos),
        row_shares=[4, 1],
    )
    return rrb.Blueprint(
        rrb.Horizontal(left, rrb.Vertical(*plots), column_shares=[3, 2]),
        collapse_panels=True,
    )


def open_recording(
    *,
    save: str | Path | None = None,
    serve: bool = False,
    url: str | None = None,
    spawn: bool = True,
    blueprint: rrb.Blueprint | None = None,
    application_id: str = APPLICATION_ID,
) -> rr.RecordingStream:
    """A new (not global) recording sending to a file, a served web viewer, a viewer at
    ``url``, or a spawned viewer — in that order of precedence; ``spawn=False`` and no other
    sink keeps it buffered. For live streaming (``mcchain run --rerun``) with
    :func:`log_samples` after each chunk; finish with ``with recording: ...`` or
    ``recording.flush()`` so a saved file is complete."""
    import rerun as rr

    rec = rr.RecordingStream(application_id)
    if save is not None:
        rec.save(save, default_blueprint=blueprint)
    elif serve:
        uri = rec.serve_grpc(default_blueprint=blueprint)
        rr.serve_web_viewer(open_browser=True, connect_to=uri)
    elif url is not None:
        rec.connect_grpc(url, default_blueprint=blueprint)
    elif spawn:
        rec.spawn(default_blueprint=blueprint)
    return rec


# -- command -----------------------------------------------------------------------------------
def _attr_int(ds: xr.Dataset, name: str) -> int | None:
    value = ds.attrs.get(name)
    try:
        return None if value is None else int(value)
    except (TypeError, ValueError):  # "none": a run without [sample]
        return None


def _open_inputs(run: str | Path) -> tuple[xr.Dataset, Model]:
    """The ensemble of a run folder and the model of the whole run (row = global sample).

    The model is recompiled from the run's ``scene.toml`` with its ``sample_count`` and
    ``seed`` attributes; a mismatch with the stored ``parameters`` is logged (the geometry
    of sampled attachment points would then be the recompiled one).
    """
    from mcchain.runs import open_run, resolve_run
    from mcchain.scene import compile_model, load_scene

    folder = resolve_run(run)
    ds = open_run(folder)
    scene = load_scene(folder / "scene.toml")
    if not ds.sizes.get("param", 0):
        return ds, compile_model(scene)
    count = _attr_int(ds, "sample_count") or int(_sample_ids(ds).max()) + 1
    seed = _attr_int(ds, "seed")
    model = compile_model(scene, nsample=count, seed=seed)
    ids = _sample_ids(ds)
    stored = np.asarray(ds["parameters"].transpose("sample", "param").values, float)
    if ids.max() >= model.nsample or not np.allclose(
        model.parameters[ids], stored, rtol=1e-12, atol=0.0, equal_nan=True
    ):
        log.warning(
            "%s: the scene recompiled (%d samples, seed %s) does not reproduce the stored "
            "parameters; sampled geometry is drawn from the recompiled model",
            run,
            count,
            seed,
        )
    return ds, model


class _ArgumentParser(argparse.ArgumentParser):
    """Usage errors as :class:`RunError` (one line through the CLI), not ``SystemExit``."""

    def error(self, message: str) -> Any:
        raise RunError(f"{self.prog}: {message}")


def build_parser() -> argparse.ArgumentParser:
    """The ``mcchain show`` parser (see :func:`add_arguments`)."""
    parser = _ArgumentParser(
        prog="mcchain show", description="replay samples of a run in the rerun viewer"
    )
    add_arguments(parser)
    return parser


def show(
    ds: xr.Dataset,
    model: Model,
    samples: Sequence[int],
    args: argparse.Namespace,
) -> None:
    """Log ``samples`` to the sink the rerun flags in ``args`` choose (``rr.script_setup``)."""
    import rerun as rr

    rr_args = argparse.Namespace(**{flag: getattr(args, flag, None) for flag in _RERUN_FLAGS})
    for flag in ("headless", "connect", "serve", "stdout"):
        setattr(rr_args, flag, bool(getattr(rr_args, flag)))
    if rr_args.save is not None:
        Path(rr_args.save).parent.mkdir(parents=True, exist_ok=True)
    magnify = float(getattr(args, "magnify", None) or DEFAULT_MAGNIFY)
    blueprint = make_blueprint(ds, model, samples, magnify)
    rec = rr.script_setup(rr_args, APPLICATION_ID, default_blueprint=blueprint)
    with rec:
        log_samples(
            ds,
            model,
            samples,
            rec,
            magnify=magnify,
            force_scale=getattr(args, "force_scale", None),
        )
    rr.script_teardown(rr_args)


def main(argv: Sequence[str] | argparse.Namespace | None = None) -> int:
    """``mcchain show RUN ...``: the command-line words after ``show`` (or parsed arguments
    of :func:`add_arguments`); prints the samples shown and, with ``--save``, the file."""
    import sys

    if isinstance(argv, argparse.Namespace):
        args = argv
    else:
        args = build_parser().parse_args(sys.argv[2:] if argv is None else list(argv))
    ds, model = _open_inputs(args.run)
    samples = select_samples(
        ds,
        parse_samples(getattr(args, "samples", None)),
        worst=getattr(args, "worst", None),
        status=getattr(args, "status", None),
        limit=getattr(args, "limit", None) or DEFAULT_LIMIT,
    )
    show(ds, model, samples, args)
    print("samples " + ",".join(str(s) for s in samples))
    if getattr(args, "save", None):
        print(args.save)
    return 0
