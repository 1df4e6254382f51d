"""Parameter paths: ``kind.name.key[i][j]`` resolved against a scene.

A sampled path (``[sample.vary]``) or a perturbation (``[simulate] perturb``) names one number
of the scene: ``body.bar.mass``, ``joint.O.points[1][0]``, ``scene.gravity[1]``; a driver is
named by its body. :func:`parse_path` resolves one into a :class:`ParamRef`, or says why it
names nothing.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from pydantic import BaseModel

from mcchain.parameters import PARAMETERS, rows_of
from mcchain.scene.fields import NAME_RE
from mcchain.scene.mechanism import Body, Driver, Force, Joint, SceneSection, Spring
from mcchain.scene.models import Scene

KINDS = ("body", "joint", "driver", "force", "spring")

SCENE_MODELS: dict[str, type[BaseModel]] = {
    "scene": SceneSection,
    "body": Body,
    "joint": Joint,
    "driver": Driver,
    "force": Force,
    "spring": Spring,
}
"""The scene model of each kind of :data:`mcchain.parameters.TABLE`."""


def _keys_of(kind: str, model: type[BaseModel]) -> dict[str, tuple[int, ...]]:
    """The sampled keys of one kind, in the order its scene model declares them; a sub-table
    (``[joint.contact]``) contributes dotted keys (``contact.stiffness``) at its place."""
    keys: dict[str, tuple[int, ...]] = {}
    for key in model.model_fields:
        if (kind, key) in PARAMETERS:
            keys[key] = PARAMETERS[kind, key].shape
        keys |= {row.key: row.shape for row in rows_of(kind) if row.key.startswith(key + ".")}
    return keys


PARAM_SHAPES: dict[str, dict[str, tuple[int, ...]]] = {
    kind: _keys_of(kind, model) for kind, model in SCENE_MODELS.items()
}
"""For each kind, the keys a sampled path may name and their array shapes (the rows of
:data:`mcchain.parameters.TABLE`, listed in the order the scene model declares its keys)."""

PERTURB_KEYS = {row.key: row.shape for row in rows_of("body") if row.dof is not None}
"""The body keys ``[simulate] perturb`` may name: those of the start state."""

_PATH_RE = re.compile(r"^(?P<head>[^\[\]]+?)(?P<idx>(\[[^\[\]]*\])*)$")


@dataclass(frozen=True)
class ParamRef:
    """A resolved parameter path ``kind.name.key[i][j]``.

    Attributes:
        kind: ``scene``, ``body``, ``joint``, ``driver``, ``force`` or ``spring``.
        name: the item's name ("" for ``scene``).
        index: the item's position in its list (0 for ``scene``).
        key: the key in the item (``mass``, ``points``, ...).
        indices: indices into the key's array, as many as its dimensions.
    """

    kind: str
    name: str
    index: int
    key: str
    indices: tuple[int, ...]

    def canonical(self) -> str:
        head = "scene" if self.kind == "scene" else f"{self.kind}.{self.name}"
        return f"{head}.{self.key}" + "".join(f"[{i}]" for i in self.indices)


def parameter_slot(ref: ParamRef) -> tuple[str, tuple[int, ...]]:
    """The model array and the index (without the sample axis) a parameter path lands in."""
    return PARAMETERS[ref.kind, ref.key].model_index(ref.index, ref.indices)


def _names_of(scene: Scene, kind: str) -> list[str]:
    return {
        "body": scene.body_names,
        "joint": scene.joint_names,
        "driver": scene.driver_names,
        "force": scene.force_names,
        "spring": scene.spring_names,
    }[kind]


def parse_path(scene: Scene, path: str, shapes: dict[str, dict[str, tuple[int, ...]]]) -> ParamRef:
    """Resolve ``path`` against ``scene``; raise ``ValueError(reason)`` if it names nothing.

    ``shapes`` is :data:`PARAM_SHAPES` (sampled parameters) or a subset of it.
    """
    m = _PATH_RE.match(path)
    if not m:
        raise ValueError("not a parameter path such as `body.bar.mass` or `joint.O.points[1][0]`")
    head, idx_text = m.group("head"), m.group("idx")
    parts = head.split(".")
    raw_indices = re.findall(r"\[([^\[\]]*)\]", idx_text)
    kinds = ", ".join(shapes)
    if parts[0] == "scene":
        if "scene" not in shapes:
            raise ValueError(f"unknown kind 'scene' (expected one of: {kinds})")
        if len(parts) != 2:
            raise ValueError("expected `scene.<key>`, e.g. `scene.gravity[1]`")
        kind, name, index, key = "scene", "", 0, parts[1]
    elif parts[0] in shapes:
        kind = parts[0]
        if len(parts) < 3 or not all(parts[1:]):
            raise ValueError(f"expected `{kind}.<name>.<key>`")
        name, key = parts[1], ".".join(parts[2:])
        names = _names_of(scene, kind)
        if name not in names:
            what = "driver (named by its body)" if kind == "driver" else kind
            known = ", ".join(names) if names else "none"
            raise ValueError(f"unknown {what} {name!r} (known: {known})")
        index = names.index(name)
    else:
        raise ValueError(f"unknown kind {parts[0]!r} (expected one of: {kinds})")
    keys = shapes[kind]
    if key not in keys:
        raise ValueError(f"unknown key {key!r} of a {kind} (expected one of: {', '.join(keys)})")
    shape = keys[key]
    indices: list[int] = []
    for text in raw_indices:
        if not text.isdigit() or (len(text) > 1 and text[0] == "0"):
            raise ValueError(f"bad index [{text}]: expected a non-negative integer")
        indices.append(int(text))
    if len(indices) != len(shape):
        if not shape:
            raise ValueError(f"`{key}` is a number and takes no index")
        dims = "".join(f"[0..{n - 1}]" for n in shape)
        raise ValueError(
            f"`{key}` needs {len(shape)} index{'es' if len(shape) > 1 else ''} "
            f"{dims}, got {len(indices)}"
        )
    for i, n in zip(indices, shape, strict=True):
        if i >= n:
            raise ValueError(f"index {i} out of range 0..{n - 1} of `{key}`")
    return ParamRef(kind, name, index, key, tuple(indices))


def quote_key(key: str) -> str:
    """A key as TOML writes it in a dotted path: bare if it can be, else quoted."""
    return key if re.fullmatch(r"[A-Za-z0-9_\-]+", key) else f'"{key}"'


def item_path(kind: str, index: int, name: str | None) -> str:
    """``kind.name`` when the item has a usable name, else ``kind[index]``."""
    if isinstance(name, str) and NAME_RE.match(name):
        return f"{kind}.{name}"
    return f"{kind}[{index}]"
