"""Loading a scene: file or TOML text or dict -> validated :class:`~mcchain.scene.models.Scene`.

Every way in runs the models, then :func:`~mcchain.scene.checks.check_scene`; a bad input
raises one :class:`~mcchain.errors.SceneError` line ``key.path: reason``.
"""

from __future__ import annotations

import os
import re
import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Any, TypeVar

from pydantic import BaseModel, ValidationError

from mcchain.errors import SceneError
from mcchain.scene.checks import check_scene
from mcchain.scene.messages import format_validation_error
from mcchain.scene.models import Scene


def load_scene(path: str | os.PathLike[str]) -> Scene:
    """Read and validate a scene file; raise :class:`SceneError` (one line) if it is bad.

    A missing or unreadable file, malformed TOML (with its line and column), a schema error
    or a cross-reference error all give ``key.path: reason`` (the file's path as the key for
    file-level errors).
    """
    p = Path(path)
    try:
        raw = p.read_bytes()
    except FileNotFoundError:
        raise SceneError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise SceneError(f"{path}: is a directory, not a scene file") from None
    except OSError as exc:
        raise SceneError(f"{path}: cannot read the file ({exc.strerror})") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise SceneError(f"{path}: not UTF-8 text (byte {exc.start})") from None
    return load_scene_text(text, name=str(path))


def load_scene_text(text: str, name: str = "<string>") -> Scene:
    """Validate a scene given as TOML text; ``name`` labels it in messages.

    When ``[scene] name`` is omitted, the scene is named after ``name``'s stem (so
    ``configs/paper-bar.toml`` gives ``paper-bar``), or ``scene`` for a ``<label>``.
    """
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{name}: malformed TOML: {exc}") from None
    return scene_from_dict(data, source=name, text=text)


def scene_from_dict(data: dict[str, Any], source: str = "<dict>", text: str = "") -> Scene:
    """Validate a scene given as the dict a TOML parser returns (see :func:`load_scene`)."""
    try:
        scene = Scene.model_validate(data)
    except ValidationError as exc:
        raise SceneError(format_validation_error(exc, data)) from None
    scene._text = text
    scene._source = source
    if scene.scene.name is None:
        scene.scene.name = _default_scene_name(source)
    check_scene(scene)
    return scene


SectionT = TypeVar("SectionT", bound=BaseModel)


def load_section(
    model: type[SectionT], section: str, data: SectionT | Mapping[str, Any]
) -> SectionT:
    """A settings section given without a scene (``simulate(model, dict(t_end=1.0, dt=1e-3))``),
    validated by its scene model, so its defaults are the schema's; a model instance is
    returned as is. A bad table raises :class:`SceneError` ``section.key: reason``.
    """
    if isinstance(data, model):
        return data
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        raise SceneError(format_validation_error(exc, data, section)) from None


def _default_scene_name(source: str) -> str:
    if source.startswith("<"):
        return "scene"
    stem = Path(source).stem
    stem = re.sub(r"[\s.\[\]\"'/\\]+", "-", stem).strip("-")
    return stem or "scene"
