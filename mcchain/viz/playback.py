"""What a sample looks like in the rerun viewer: its entities, logged from an ensemble
(:func:`log_samples`), the default layout (:func:`make_blueprint`) and the recording's sink
(:func:`open_recording`).

``mcchain show`` (:mod:`mcchain.viz.show`) replays samples of a run with it, and ``mcchain
run --rerun`` streams them live (:mod:`mcchain.viz.live`). What each sample looks like comes
from the ensemble itself (its stored scene text and parameters,
:func:`mcchain.ensemble.describe.stored_model`).

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
``sample/{i}/orbit/{joint}/...``         the journal orbit d / c of a clearance joint
                                         (:mod:`mcchain.viz.contact`): ``circle``
                                         LineStrips2D (static, the unit circle),
                                         ``path`` Points2D (static, every time) and
                                         ``journal`` Points2D (now), coloured by state
                                         (link, contact, free, link after contact lost)
``sample/{i}/joint_force/{joint}``       Scalars [x, y] (N)
``sample/{i}/contact_force/{joint}``     Scalars λ of clearance joints (N)
``sample/{i}/driver_torque/{driver}``    Scalars (N m)
``sample/{i}/driver_force/{driver}``     Scalars of slider drivers (N)
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

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from mcchain.ensemble.queries import positions, sample_ids
from mcchain.errors import RunError
from mcchain.model import JOINT_CLEARANCE, Model
from mcchain.status import Status
from mcchain.viz import contact, geometry

if TYPE_CHECKING:
    import rerun as rr
    import rerun.blueprint as rrb
    import xarray as xr


APPLICATION_ID = "mcchain"
DEFAULT_MAGNIFY = 100.0
"""Default magnification of clearance offsets: 0.1 mm is drawn as 1 cm."""
ORBIT_SPACING = 2.5
"""Distance between the orbit diagrams of a sample's clearance joints (in clearances)."""
FORCE_ARROW_FRACTION = 0.3
"""Default force scale: the largest force shown is drawn this fraction of the mechanism size."""

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


# -- one sample as arrays ----------------------------------------------------------------------
@dataclass(frozen=True)
class _Track:
    """The arrays that draw one sample (time first)."""

    time: np.ndarray
    q: np.ndarray
    joint_force: np.ndarray
    contact_force: np.ndarray | None
    driver_torque: np.ndarray | None
    driver_force: np.ndarray | None
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
            _values(ds, "driver_force", pos, "time", "driver"),
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
    return _Track(np.zeros(1), q[None], jf[None], None, None, None, None, None)


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
    for pos in positions(ds, samples):
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
        dataset: an ensemble (the registry's variables) or the chunk of it being computed; only
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
    where = positions(dataset, samples)
    if force_scale is None:
        force_scale = default_force_scale(dataset, model, samples, model_offset=model_offset)
    for sample, pos in zip(samples, where, strict=True):
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

    orbit = contact.sample_orbit(ds, model, pos, row, track.q) if "q" in ds.data_vars else None
    if orbit is not None:
        _log_orbit(f"{root}/orbit", orbit, times, rec, rr)

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
    for what, values in (
        ("driver_torque", track.driver_torque),
        ("driver_force", track.driver_force),
    ):
        if values is None:
            continue
        for k, name in enumerate(model.driver_names):
            if np.isfinite(values[:, k]).any():  # a slider driver has a force, not a torque
                scalars(f"{root}/{what}/{_part(name)}", values[:, k], [name])
    if track.energy is not None:
        scalars(f"{root}/energy", track.energy, ["energy"])
    if track.constraint_error is not None:
        scalars(f"{root}/constraint_error", track.constraint_error, ["max |Φ|"])


def _log_orbit(
    path: str, orbit: contact.Orbit, times: list[Any], rec: rr.RecordingStream | None, rr: Any
) -> None:
    """The journal orbit d / c of each clearance joint under ``path/{joint}``: the unit
    clearance circle and the whole orbit (static), the journal now (over time), coloured by
    state (:data:`mcchain.viz.contact.STATES`); joint k is drawn ORBIT_SPACING · k to the
    right, y negated as in the mechanism view."""
    circle = geometry.circles(np.zeros((1, 2)), 1.0, 91)[0]
    for at, name in enumerate(orbit.names):
        shift = np.array([ORBIT_SPACING * at, 0.0])
        where = f"{path}/{_part(name)}"
        offset = _flip(orbit.offset[:, at]) + shift
        colors = contact.STATE_COLORS[orbit.state[:, at]]
        c_mm = 1e3 * float(orbit.clearance[at])
        rr.log(
            f"{where}/circle",
            rr.LineStrips2D([circle + shift], colors=JOINT_COLOR, radii=-1.0,
                            labels=[f"{name}: c = {c_mm:.4g} mm"]),
            static=True, recording=rec,
        )  # fmt: skip
        rr.log(f"{where}/path", rr.Points2D(offset, colors=colors, radii=-1.5), static=True,
               recording=rec)  # fmt: skip
        rr.log(f"{where}/journal", rr.Points2D.from_fields(radii=-6.0), static=True, recording=rec)
        rr.send_columns(
            f"{where}/journal",
            indexes=times,
            columns=rr.Points2D.columns(positions=offset, colors=colors).partition(
                [1] * len(offset)
            ),
            recording=rec,
        )


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
    for sample, pos in zip(samples, positions(ds, samples), strict=True):
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

    present = set(sample_ids(ds).tolist())
    x_range, y_range = view_bounds(
        ds, model, [s for s in samples if s in present], magnify, model_offset
    )
    bounds = rrb.VisualBounds2D(x_range=x_range, y_range=y_range)
    mechanisms: list[Any] = [
        rrb.Spatial2DView(origin=f"/sample/{s}/mechanism", name=f"sample {s}", visual_bounds=bounds)
        for s in samples
    ]
    nclear = int(np.sum(np.asarray(model.joint_kind) == JOINT_CLEARANCE))
    if nclear and "q" in ds.data_vars:  # the journal orbit beside each mechanism
        orbit_bounds = rrb.VisualBounds2D(
            x_range=[-1.3, ORBIT_SPACING * (nclear - 1) + 1.3], y_range=[-1.3, 1.3]
        )
        mechanisms = [
            rrb.Horizontal(
                view,
                rrb.Spatial2DView(
                    origin=f"/sample/{s}/orbit",
                    name=f"sample {s}: orbit d / c",
                    visual_bounds=orbit_bounds,
                ),
                column_shares=[3, 1],
            )
            for s, view in zip(samples, mechanisms, strict=True)
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
    if "driver_force" in ds.data_vars and model.ndriver:
        plots.append(series("driver force (N)", "driver_force/**"))
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
