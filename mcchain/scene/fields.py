"""The building blocks of the scene models (:mod:`mcchain.scene.models`): the field types
(finite numbers, strict integers, names) and the strict base of every section, which forbids
unknown keys."""

from __future__ import annotations

import re
from typing import Annotated, Any

from pydantic import (
    AfterValidator,
    AllowInfNan,
    BaseModel,
    ConfigDict,
    Field,
    Strict,
)

GROUND_NAME = "ground"
"""The name of the fixed body in ``bodies``/``body`` keys."""

Num = Annotated[float, Strict(), AllowInfNan(False)]
"""A finite number (TOML int or float)."""
Int = Annotated[int, Strict()]
"""A TOML integer (a float such as 10.0 is refused)."""
Bool = Annotated[bool, Strict()]
"""A TOML boolean (``true``/``false``; a string such as ``"yes"`` or a number is refused)."""
Vec2 = Annotated[list[Num], Field(min_length=2, max_length=2)]
"""Two finite numbers ``[x, y]``."""
Points = Annotated[list[Vec2], Field(min_length=2, max_length=2)]
"""Two local points ``[[xa, ya], [xb, yb]]``, one on each of the two bodies."""

NAME_RE = re.compile(r"^[^\s.\[\]\"'/\\]+$")


def _check_name(value: str) -> str:
    if not NAME_RE.match(value):
        raise ValueError(
            f"invalid name {value!r}: use a non-empty name without spaces, dots, brackets, "
            "quotes or slashes"
        )
    return value


Name = Annotated[str, Strict(), AfterValidator(_check_name)]
"""A name: non-empty, without whitespace, ``.``, ``[``, ``]``, quotes or slashes (they
delimit sampled paths such as ``body.bar.position[0]`` and run folder names)."""
BodyRef = Annotated[str, Strict()]
"""The name of a body, or ``"ground"``."""


class Section(BaseModel):
    """A scene table: unknown keys are refused, defaults are not validated again."""

    model_config = ConfigDict(extra="forbid", validate_default=False)


def flatten_dotted(value: Any, is_leaf: Any) -> Any:
    """Undo TOML's dotted bare keys: ``{"body": {"bar": {"mass": X}}}`` -> ``{"body.bar.mass": X}``.

    A sampled path should be a quoted key (``"body.bar.mass" = {...}``); written bare, TOML
    nests it. A nested table is flattened while it is not a leaf (a distribution table).
    """
    if not isinstance(value, dict):
        return value
    out: dict[str, Any] = {}

    def walk(prefix: str, node: Any) -> None:
        if isinstance(node, dict) and node and not is_leaf(node):
            for key, sub in node.items():
                walk(f"{prefix}.{key}" if prefix else key, sub)
        elif prefix in out:
            raise ValueError(f"path {prefix!r} given twice (as a quoted key and as dotted keys)")
        else:
            out[prefix] = node

    for key, sub in value.items():
        walk(key, sub)
    return out
