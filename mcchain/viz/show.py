"""``mcchain show``: replay samples of a run in the rerun viewer.

``mcchain show RUN --samples 0,17 [--save FILE.rrd | --spawn | --serve]`` draws each chosen
sample of a run (:func:`show_run`) as :mod:`mcchain.viz.playback` draws samples. Samples may
also be picked by a criterion (:func:`mcchain.ensemble.queries.select_samples`): ``--worst
VARIABLE:N`` takes the N samples with the largest peak ``|VARIABLE|`` (e.g. ``--worst
contact_force:3``) and ``--failed NAME`` those failing requirement NAME (farthest beyond its
limit first), and ``--status contact_lost`` those whose status carries a flag (names of
:attr:`mcchain.status.Status.meaning`, plus ``ok``; with both, the worst N of the samples
with that status). The model of the samples is rebuilt from what the ensemble stores
(:func:`open_inputs`).
"""

from __future__ import annotations

import os
import sys
from collections.abc import Sequence
from pathlib import Path
from types import SimpleNamespace
from typing import TYPE_CHECKING, Any

import numpy as np

from mcchain.ensemble.histories import select_with_histories
from mcchain.ensemble.queries import DEFAULT_LIMIT, select_samples
from mcchain.errors import RunError
from mcchain.viz.playback import APPLICATION_ID, DEFAULT_MAGNIFY, log_samples, make_blueprint

if TYPE_CHECKING:
    import xarray as xr

    from mcchain.model import Model


def viewer_cannot_spawn(flag: str) -> RunError | None:
    """Why a spawned rerun viewer cannot open here, as the error to raise for ``flag`` (the
    option that asked for it), or ``None``: on Linux the viewer is a desktop window and needs
    a display; without one the spawned process dies and the recording is lost."""
    if not sys.platform.startswith("linux"):
        return None
    if any(os.environ.get(name) for name in ("DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET")):
        return None
    return RunError(
        f"{flag}: no display to open the rerun viewer on (neither DISPLAY nor WAYLAND_DISPLAY "
        "is set): save the recording with --save FILE.rrd (then `rerun FILE.rrd` where there "
        "is a display) or serve a web viewer with --serve"
    )


def open_inputs(run: str | Path) -> tuple[xr.Dataset, Model]:
    """The ensemble of a run folder and the model of its samples (row = global sample).

    The model is rebuilt from what the ensemble stores (its scene text and ``parameters``,
    :func:`mcchain.ensemble.describe.stored_model`), never by sampling the scene again.
    """
    from mcchain.ensemble.describe import stored_model
    from mcchain.runner.runs import open_run, resolve_run

    ds = open_run(resolve_run(run))
    return ds, stored_model(ds)


def show(
    ds: xr.Dataset,
    model: Model,
    samples: Sequence[int],
    *,
    save: str | Path | None = None,
    serve: bool = False,
    connect: bool = False,
    url: str | None = None,
    stdout: bool = False,
    headless: bool = False,
    magnify: float | None = None,
    force_scale: float | None = None,
) -> None:
    """Log ``samples`` to one sink, chosen as ``rr.script_setup`` does: ``save`` (a file,
    its folder created), ``serve``, ``connect`` (to ``url``), ``stdout``, ``headless``, or by
    default a spawned viewer."""
    import rerun as rr

    # rr.script_setup reads its sink from the attributes of parsed arguments: these, given
    # by name here (mcchain parses its command line in mcchain.cli only).
    rr_args: Any = SimpleNamespace(
        headless=bool(headless),
        connect=bool(connect),
        serve=bool(serve),
        url=url,
        save=None if save is None else str(save),
        stdout=bool(stdout),
    )
    spawned = not (headless or connect or serve or stdout or rr_args.save is not None)
    refusal = viewer_cannot_spawn("show") if spawned else None
    if refusal is not None:
        raise refusal
    if rr_args.save is not None:
        Path(rr_args.save).parent.mkdir(parents=True, exist_ok=True)
    magnify = float(magnify or DEFAULT_MAGNIFY)
    blueprint = make_blueprint(ds, model, samples, magnify)
    rec = rr.script_setup(rr_args, APPLICATION_ID, default_blueprint=blueprint)
    try:
        with rec:
            log_samples(ds, model, samples, rec, magnify=magnify, force_scale=force_scale)
    except RuntimeError as exc:  # rerun's flush: the viewer never answered
        where = "the spawned viewer" if spawned else f"the viewer at {url or 'the default url'}"
        raise RunError(f"show: {where} could not be reached: {exc}") from None
    rr.script_teardown(rr_args)


def failed_samples(ds: Any, name: str, limit: int) -> list[int]:
    """``--failed NAME``: the samples that fail requirement ``name``, farthest beyond its
    limit first (failed instances, whose output is NaN, after them), at most ``limit``.

    Raises:
        RunError: no such requirement in the run, or no sample fails it.
    """
    from mcchain.decision.requirements import requirement_values, stored_requirements
    from mcchain.decision.summary import met_of

    requirements = {r.name: r for r in stored_requirements(ds)}
    if name not in requirements:
        known = ", ".join(requirements) or "none"
        raise RunError(f"--failed: no requirement {name!r} in the run (requirements: {known})")
    requirement = requirements[name]
    values = requirement_values(ds, requirement)
    where = np.flatnonzero(met_of(ds, requirement, values) == 0)
    if where.size == 0:
        raise RunError(f"--failed: no sample fails requirement {name!r}")
    beyond = np.zeros(where.size)
    x = values[where]
    if requirement.max is not None:
        beyond = np.maximum(beyond, x - requirement.max)
    if requirement.min is not None:
        beyond = np.maximum(beyond, requirement.min - x)
    order = np.argsort(np.where(np.isnan(beyond), -np.inf, -beyond), kind="stable")
    ids = np.asarray(ds["sample"].values)
    return [int(ids[i]) for i in where[order][:limit]]


def show_run(
    run: str | Path,
    samples: Sequence[int] = (),
    *,
    worst: str | None = None,
    status: str | None = None,
    limit: int | None = None,
    failed: str | None = None,
    **options: Any,
) -> list[int]:
    """``mcchain show``: pick samples of a run (:func:`~mcchain.ensemble.queries.select_samples`;
    ``failed``: those failing that requirement, :func:`failed_samples`) and :func:`show`
    them; ``options`` are :func:`show`'s sink and drawing options. Returns the samples
    shown."""
    ds, model = open_inputs(run)
    if failed is not None:
        samples = [*samples, *failed_samples(ds, failed, limit or DEFAULT_LIMIT)]
    chosen = select_samples(ds, samples, worst=worst, status=status, limit=limit or DEFAULT_LIMIT)
    # A light run ([storage] histories) may not hold a chosen sample's history: say so.
    show(select_with_histories(ds, chosen), model, chosen, **options)
    return chosen
