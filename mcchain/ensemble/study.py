"""Which study an ensemble file belongs to: its global attributes without what only says
how far it was extended or how a session ran.

A run that grows (``--extend``, ``until``) or resumes merges part files written by several
sessions; :func:`study_attributes` is what they must share, :func:`study_differences` says in
words what makes two files two studies (an ``--extend`` of another version's folder is refused
with it before anything is computed).
"""

from __future__ import annotations

from collections.abc import Mapping
from contextlib import suppress
from pathlib import Path
from typing import Any

import numpy as np

SESSION_ATTRIBUTES = ("kernel_compiler",)
"""Global attributes that say how a session ran, not what the study is: not compared
between parts. The merged file carries the first part's (a run that grew: the merging
session's); run.json's sessions record every session's."""


def study_attributes(attrs: Mapping[str, Any]) -> dict[str, Any]:
    """Global attributes without the sample count (``sample_count``, ``settings``'
    ``samples``) and how the verdicts are judged (``settings``' ``sequential``, which an
    ``--extend`` of a fixed-count run adds): what the parts of one study share however far
    it was extended."""
    import json

    out = {key: value for key, value in attrs.items() if key != "sample_count"}
    if isinstance(out.get("settings"), str):
        with suppress(ValueError):
            settings = json.loads(out["settings"])
            if isinstance(settings, dict):
                settings.pop("samples", None)
                settings.pop("sequential", None)
                out["settings"] = json.dumps(settings, sort_keys=True)
    return out


def study_differences(
    ours: Mapping[str, Any], theirs: Mapping[str, Any], *, most: int = 6
) -> list[str]:
    """What makes two sets of global attributes two studies (as the merge compares them,
    :func:`study_attributes` without the session's): one phrase per differing attribute, or
    per differing key of the ``settings`` and ``versions`` JSON (``scene.simulate.retry_failed:
    absent there, true here``); at most ``most`` phrases, then how many more."""
    import json

    def flat(value: Any, prefix: str) -> dict[str, Any]:
        if isinstance(value, dict):
            out: dict[str, Any] = {}
            for key, item in value.items():
                out.update(flat(item, f"{prefix}.{key}" if prefix else str(key)))
            return out
        return {prefix: value}

    def decoded(attrs: Mapping[str, Any]) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for key, value in study_attributes(attrs).items():
            if key in SESSION_ATTRIBUTES:
                continue
            parsed = None
            if key in ("settings", "versions") and isinstance(value, str):
                with suppress(ValueError):
                    parsed = json.loads(value)
            out.update(flat(parsed, key) if isinstance(parsed, dict) else {key: value})
        return out

    here, there = decoded(ours), decoded(theirs)
    phrases = []
    for key in sorted(set(here) | set(there)):
        if key in here and key in there and same_values(here[key], there[key]):
            continue
        shown = [
            "absent" if key not in side else json.dumps(side[key], default=str)[:60]
            for side in (there, here)
        ]
        phrases.append(f"{key}: {shown[0]} there, {shown[1]} here")
    if len(phrases) > most:
        phrases = [*phrases[:most], f"{len(phrases) - most} more"]
    return phrases


def file_attributes(path: Path) -> dict[str, Any]:
    """The global attributes of a netCDF file (an ensemble or a part)."""
    import netCDF4

    with netCDF4.Dataset(path) as nc:
        return attributes_of(nc)


def attributes_of(obj: Any) -> dict[str, Any]:
    """The global attributes of an open netCDF4 Dataset (or a variable's)."""
    return {key: obj.getncattr(key) for key in obj.ncattrs()}


def same_values(a: Any, b: Any) -> bool:
    """Equal values, arrays and scalars alike (an attribute read back may be either)."""
    return bool(np.array_equal(np.asarray(a), np.asarray(b)))
