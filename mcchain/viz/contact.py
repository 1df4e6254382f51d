"""What the clearance joints of a run did, for the viewers: their model, their state over
time, the journal orbit.

* :func:`joint_models`: per joint, the model its history comes from — ``"link"`` (the
  paper's massless link), ``"contact"``, ``"auto"``, or ``"contact law"`` when a law was used
  but the run does not say which model chose it; ``None`` for ideal joints.
* :func:`joint_states`: per time and joint, one of :data:`STATES` — the ensemble's
  ``contact_mode`` (link, contact, free), refined by the sample's status: a link after the
  sample's ``contact_lost_time`` is :data:`LINK_LOST` (the link then pulls: its reactions are
  not physical), a joint with a law whose ``contact_mode`` is −1 is :data:`FAILED`.
* :func:`sample_orbit`: the journal orbit d / c (the clearance circle is the unit circle) of
  every clearance joint of one sample, with those states. ``mcchain report`` draws it for the
  worst samples, ``mcchain show`` beside the mechanism.

Pure numpy and xarray reads; no plotting library.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from mcchain.contact import MODE_CONTACT, MODE_FREE, MODE_LINK, MODEL_NAMES
from mcchain.model import JOINT_CLEARANCE, Model
from mcchain.viz import geometry

if TYPE_CHECKING:
    import xarray as xr

LINK, CONTACT, FREE = MODE_LINK, MODE_CONTACT, MODE_FREE
"""States that are the ensemble's ``contact_mode`` values."""
LINK_LOST = 3
"""The link model after the sample's ``contact_lost_time`` (λ ≤ 0 was needed: invalid)."""
FAILED = 4
"""A joint with a contact law whose ``contact_mode`` is −1 (the sample failed)."""
STATES = ("link", "contact", "free", "link after contact lost", "failed")
"""State names, indexed by state code."""
STATE_COLORS = np.array(
    [[31, 119, 180], [214, 39, 40], [44, 160, 44], [148, 103, 189], [127, 127, 127]],
    dtype=np.uint8,
)
"""RGB of each state (link blue, contact red, free green, invalid link purple, failed grey)."""


def law_joints(ds: xr.Dataset, model: Model | None = None) -> np.ndarray:
    """(njoint,) bool: which joints may use a contact law in the run's histories — from the
    model when given, else from ``contact_mode`` (a joint with a value >= 0)."""
    njoint = ds.sizes.get("joint", 0)
    if model is not None:
        return np.asarray(model.joint_model)[:njoint] != 0
    if "contact_mode" not in ds.data_vars:
        return np.zeros(njoint, dtype=bool)
    mode = ds["contact_mode"].transpose("joint", ...)
    return np.asarray((mode >= 0).any([d for d in mode.dims if d != "joint"]).values, bool)


def joint_models(ds: xr.Dataset, model: Model | None = None) -> list[str | None]:
    """Per joint, the model of its time history (see the module docstring).

    Without a model, a clearance joint is one whose ``contact_force`` has a finite value.
    """
    njoint = ds.sizes.get("joint", 0)
    law = law_joints(ds, model)
    if model is not None:
        clear = np.asarray(model.joint_kind)[:njoint] == JOINT_CLEARANCE
        codes = np.asarray(model.joint_model)[:njoint]
        return [
            MODEL_NAMES.get(int(code), "contact law") if c else None
            for c, code in zip(clear, codes, strict=True)
        ]
    clear = np.zeros(njoint, dtype=bool)
    if "contact_force" in ds.data_vars:
        cf = ds["contact_force"].transpose("joint", ...)
        clear = np.asarray(cf.notnull().any([d for d in cf.dims if d != "joint"]).values, bool)
    return [
        "contact law" if is_law else ("link" if c else None)
        for is_law, c in zip(law, clear | law, strict=True)
    ]


def joint_states(
    mode: np.ndarray | None, law: np.ndarray, time: np.ndarray, lost_time: float
) -> np.ndarray:
    """States (T, nj) of some joints of one sample (codes of :data:`STATES`).

    Args:
        mode: (T, nj) the sample's ``contact_mode`` at those joints, or ``None`` (the run has
            no contact law: every joint is the link).
        law: (nj,) bool, whether each joint has a contact law.
        time: (T,) s.
        lost_time: the sample's ``contact_lost_time`` (NaN if it never lost contact).
    """
    nt, nj = len(time), len(law)
    states = np.full((nt, nj), LINK, dtype=np.int8)
    if mode is not None:
        mode = np.asarray(mode).reshape(nt, nj)
        states = np.where(law[None, :] & (mode < 0), FAILED, np.where(mode > 0, mode, LINK))
        states = states.astype(np.int8)
    if np.isfinite(lost_time):
        after = np.asarray(time)[:, None] >= lost_time
        states[after & (states == LINK)] = LINK_LOST
    return states


@dataclass(frozen=True)
class Orbit:
    """The journal orbit of one sample's clearance joints.

    Attributes:
        joints: (nj,) indices of the clearance joints.
        names: their names.
        time: (T,) s.
        offset: (T, nj, 2) d / c (dimensionless; the clearance circle is the unit circle).
        state: (T, nj) int8 codes of :data:`STATES`.
        clearance: (nj,) c, m.
    """

    joints: np.ndarray
    names: tuple[str, ...]
    time: np.ndarray
    offset: np.ndarray
    state: np.ndarray
    clearance: np.ndarray


def sample_orbit(
    ds: xr.Dataset, model: Model, pos: int, row: int, q: np.ndarray | None = None
) -> Orbit | None:
    """The orbit of the sample at position ``pos`` of ``ds`` (model row ``row``), from its
    positions ``q`` (T, nbody, 3) (read from ``ds`` when not given) and the model's joint
    points; ``None`` if the run has no history or the model no clearance joint."""
    joints = np.flatnonzero(np.asarray(model.joint_kind) == JOINT_CLEARANCE)
    if "q" not in ds.data_vars or not len(joints):
        return None
    time = np.asarray(ds["time"].values, dtype=np.float64)
    if q is None:
        da = ds["q"].isel(sample=pos).transpose("time", "body", "dof")
        q = np.asarray(da.values, dtype=np.float64)
    offset = geometry.normalised_offsets(model, row, q)[:, joints]
    mode = None
    if "contact_mode" in ds.data_vars:
        da = ds["contact_mode"].isel(sample=pos, joint=joints).transpose("time", "joint")
        mode = np.asarray(da.values)
    lost = np.nan
    if "contact_lost_time" in ds.data_vars:
        lost = float(ds["contact_lost_time"].isel(sample=pos).values)
    law = np.asarray(model.joint_model)[joints] != 0
    clearance = geometry._at(model.joint_clearance, row).reshape(-1)[joints]
    return Orbit(
        joints,
        tuple(model.joint_names[k] for k in joints),
        time,
        offset,
        joint_states(mode, law, time, lost),
        clearance,
    )
