"""What an ensemble says about itself: its scene, its settings, the model of its samples.

``ensemble.nc`` (and every part file) carries the scene file's text (attribute ``scene``),
the resolved settings (``settings``, JSON) and the sampled values (``parameters``, one
column per ``[sample.vary]`` path). That is enough to rebuild the model of the stored
samples without drawing them again: :func:`stored_model` compiles the nominal scene once
and writes the stored columns where each path lands. The sampler is never called, so an old
run draws the same geometry after the sampling code changes.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np

from mcchain.errors import RunError
from mcchain.model import JOINT_CLEARANCE, Model, constraint_rows

if TYPE_CHECKING:
    import xarray as xr

SCENE_NAME = "scene.toml"
"""How the stored scene text is labelled in messages (the run folder's copy)."""


def stored_settings(ds: xr.Dataset) -> dict[str, Any]:
    """The resolved settings the ensemble stores (``{}`` if it has none)."""
    try:
        settings = json.loads(str(ds.attrs.get("settings", "")))
    except ValueError:
        return {}
    return settings if isinstance(settings, dict) else {}


def stored_scene_text(ds: xr.Dataset) -> str:
    """The scene file's text the ensemble was made from."""
    text = ds.attrs.get("scene")
    if not isinstance(text, str):
        raise RunError("the ensemble has no scene attribute: it does not describe its model")
    return text


def model_of_values(scene_text: str, paths: Sequence[str], values: np.ndarray) -> Model:
    """The model of given samples: the nominal scene compiled once (no ``[sample]``, one
    instance), with column ``j`` of ``values`` (nsample, len(paths)) written into the model
    slot ``paths[j]`` lands in. No value is drawn.

    A joint whose clearance is a column is a clearance joint (as the compiler makes it).
    Values the compiler derives from a sampled one (a driver's default ``angle0`` from a
    sampled body angle, a spring's default rest length from sampled points) keep their
    nominal value: nothing drawn depends on them.

    This is the one place outside :mod:`mcchain.scene` that knows where a parameter path
    lands (``parse_path`` + ``parameter_slot``).
    """
    from mcchain.scene import compile_model, load_scene_text, parameter_slot, parse_path
    from mcchain.scene.paths import PARAM_SHAPES

    scene = load_scene_text(scene_text, SCENE_NAME)
    nominal = compile_model(scene.model_copy(update={"sample": None}))
    values = np.asarray(values, dtype=np.float64)
    nsample = values.shape[0]
    values = values.reshape(nsample, len(paths))
    arrays: dict[str, np.ndarray] = {}
    kind = nominal.joint_kind.copy()
    for j, path in enumerate(paths):
        name, idx = parameter_slot(parse_path(scene, path, PARAM_SHAPES))
        if name not in arrays:
            arrays[name] = np.repeat(getattr(nominal, name), nsample, axis=0)
        where: tuple[slice | int, ...] = (slice(None), *idx)
        arrays[name][where] = values[:, j]
        if name == "joint_clearance":
            kind[idx[0]] = JOINT_CLEARANCE
    joint_row, driver_row = constraint_rows(kind, nominal.ndriver)
    changes: dict[str, Any] = {
        **arrays,
        "param_paths": tuple(paths),
        "parameters": np.ascontiguousarray(values),
        "nsample": nsample,
        "joint_kind": kind,
        "joint_row": joint_row,
        "driver_row": driver_row,
        "meta": {"scene_name": nominal.meta.get("scene_name"), "nsample": nsample},
    }
    return replace(nominal, **changes)


def stored_model(ds: xr.Dataset) -> Model:
    """The model of the ensemble's samples, row = global sample index.

    Built from the stored scene text and ``parameters`` (:func:`model_of_values`). Its rows
    run from 0 to the largest sample index the dataset holds (an unfinished run may lack
    some chunks: their rows are NaN).
    """
    text = stored_scene_text(ds)
    if "sample" in ds.coords:
        ids = np.asarray(ds["sample"].values, dtype=np.int64)
    else:
        ids = np.arange(ds.sizes.get("sample", 0), dtype=np.int64)
    nrow = int(ids.max()) + 1 if len(ids) else 1
    if "parameters" in ds.data_vars and ds.sizes.get("param", 0):
        paths = [str(p) for p in ds["param"].values]
        stored = np.asarray(ds["parameters"].transpose("sample", "param").values, np.float64)
    else:
        paths, stored = [], np.empty((len(ids), 0))
    values = np.full((nrow, len(paths)), np.nan)
    values[ids] = stored
    return model_of_values(text, paths, values)
