"""Pydantic validation errors turned into one line ``key.path: reason``.

The location is spelled as a scene key path, naming list items by their name
(``body.bar.mass`` rather than ``body[0].mass``), and the reason in TOML terms ("expected a
number, got the string 'x'").
"""

from __future__ import annotations

import difflib
import types
from typing import Annotated, Any, Union, get_args, get_origin

from pydantic import BaseModel, ValidationError
from pydantic.fields import FieldInfo

from mcchain.scene.models import Scene
from mcchain.scene.paths import KINDS, item_path, quote_key
from mcchain.scene.study import Distribution


def format_validation_error(exc: ValidationError, data: Any, section: str | None = None) -> str:
    """The first error of ``exc`` as ``key.path: reason`` (list items named when they can be).

    ``exc`` comes from validating a whole scene (``data``), or from validating one settings
    ``section`` alone (``data`` is then that section's table).
    """
    err = _first_error(exc.errors(include_url=False))
    loc = tuple(err["loc"])
    if section is not None:
        loc, data = (section, *loc), {section: data}
    path = loc_path(loc, data)
    return f"{path}: {_reason(err, loc)}"


def _first_error(errors: list[Any]) -> Any:
    """The error to report: the first, except that an unknown key beside a missing one in the
    same table comes first (``masss = 2.0`` is a typo of ``mass``, not a missing ``mass``)."""
    first = errors[0]
    if first["type"] == "missing":
        parent = tuple(first["loc"])[:-1]
        for err in errors:
            if err["type"] == "extra_forbidden" and tuple(err["loc"])[:-1] == parent:
                return err
    return first


def loc_path(loc: tuple[str | int, ...], data: Any) -> str:
    """Turn a pydantic location into a scene key path, naming list items by their name.

    ``("body", 0, "mass")`` -> ``body.bar.mass`` when body 0 is named ``bar`` (a driver is
    named by its ``body``), else ``body[0].mass``; dict keys that are not bare TOML keys are
    quoted: ``sample.vary."body.bar.mass".normal``.
    """
    parts: list[str] = []
    node: Any = data
    for i, elem in enumerate(loc):
        if isinstance(elem, int):
            parent = loc[i - 1] if i > 0 else None
            item = node[elem] if isinstance(node, list) and 0 <= elem < len(node) else None
            if i == 1 and (parent in KINDS or parent in ("requirement", "output")) and parts:
                key = "body" if parent == "driver" else "name"
                name = item.get(key) if isinstance(item, dict) else None
                parts[-1] = item_path(str(parent), elem, name)
            elif parts:
                parts[-1] += f"[{elem}]"
            else:
                parts.append(f"[{elem}]")
            node = item
        else:
            parts.append(quote_key(elem))
            node = node.get(elem) if isinstance(node, dict) else None
    return ".".join(parts) if parts else "scene"


def _strip(tp: Any) -> Any:
    while True:
        origin = get_origin(tp)
        if origin is Annotated:
            tp = get_args(tp)[0]
        elif origin in (Union, types.UnionType):
            args = [a for a in get_args(tp) if a is not type(None)]
            if len(args) != 1:
                return tp
            tp = args[0]
        else:
            return tp


def _schema_at(loc: tuple[str | int, ...]) -> Any:
    """The schema type at a location (a model class, list[...], dict[...], ...) or None."""
    tp: Any = Scene
    for elem in loc:
        tp = _strip(tp)
        origin = get_origin(tp)
        if isinstance(elem, int):
            if origin is not list:
                return None
            tp = get_args(tp)[0]
        elif isinstance(tp, type) and issubclass(tp, BaseModel):
            field = tp.model_fields.get(elem)
            if field is None:
                return None
            tp = field.annotation
        elif origin is dict:
            tp = get_args(tp)[1]
        else:
            return None
    return _strip(tp)


def _describe(value: Any) -> str:
    """A TOML-flavoured description of an input value."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f"the string {value!r}"
    if isinstance(value, dict):
        return "a table"
    if isinstance(value, list):
        return "an array"
    if isinstance(value, int | float):
        return repr(value)
    return f"a {type(value).__name__}"


def _reason(err: Any, loc: tuple[str | int, ...]) -> str:
    kind = err["type"]
    ctx = err.get("ctx") or {}
    value = err.get("input")
    if kind == "missing":
        return "missing required key"
    if kind == "extra_forbidden":
        parent = _schema_at(loc[:-1])
        allowed = (
            list(parent.model_fields)
            if isinstance(parent, type) and issubclass(parent, BaseModel)
            else []
        )
        if parent is Distribution:
            return f"unknown distribution (expected one of: {', '.join(allowed)})"
        what = "section" if parent is Scene else "key"
        close = difflib.get_close_matches(str(loc[-1]), allowed, n=1)
        hint = f"did you mean `{close[0]}`? " if close else ""
        return f"unknown {what} ({hint}expected one of: {', '.join(allowed)})"
    if kind in ("float_type", "float_parsing"):
        return f"expected a number, got {_describe(value)}"
    if kind == "finite_number":
        return f"must be a finite number, got {_describe(value)}"
    if kind in ("int_type", "int_parsing", "int_from_float"):
        return f"expected an integer, got {_describe(value)}"
    if kind in ("string_type",):
        return f"expected a string, got {_describe(value)}"
    if kind == "bool_type":
        return f"expected true or false, got {_describe(value)}"
    if kind in ("list_type", "tuple_type"):
        target = loc[-1] if loc else ""
        if len(loc) == 1 and target in KINDS:
            return f"expected an array of tables [[{target}]], got {_describe(value)}"
        return f"expected an array, got {_describe(value)}"
    if kind in ("model_type", "model_attributes_type", "dict_type"):
        if _schema_at(loc) is Distribution:
            return (
                f"expected a distribution table such as {{ uniform = [low, high] }}, "
                f"got {_describe(value)}"
            )
        return f"expected a table, got {_describe(value)}"
    if kind in ("too_short", "too_long"):
        lo = _min_max(loc)
        n = len(value) if isinstance(value, list | dict) else ctx.get("actual_length")
        return f"expected {lo}, got {n}"
    bounds = {
        "greater_than": (">", "gt"),
        "greater_than_equal": (">=", "ge"),
        "less_than": ("<", "lt"),
        "less_than_equal": ("<=", "le"),
    }
    if kind in bounds:
        op, key = bounds[kind]
        return f"must be {op} {ctx.get(key)!r}, got {_describe(value)}"
    if kind == "literal_error":
        return f"must be one of {ctx.get('expected')}, got {_describe(value)}"
    if kind in ("value_error", "assertion_error"):
        return str(ctx.get("error", err["msg"]))
    return str(err["msg"])


def _min_max(loc: tuple[str | int, ...]) -> str:
    """The length rule of the sequence at ``loc``: "2", "at least 1", ..."""
    metadata: list[Any] = []
    parent = _schema_at(loc[:-1])
    last = loc[-1] if loc else None
    tp: Any = None
    if isinstance(parent, type) and issubclass(parent, BaseModel) and isinstance(last, str):
        field = parent.model_fields.get(last)
        if field is not None:
            metadata.extend(field.metadata)
            tp = field.annotation
    elif get_origin(parent) is list and isinstance(last, int):
        tp = get_args(parent)[0]
    while get_origin(tp) in (Annotated, Union, types.UnionType):
        args = get_args(tp)
        if get_origin(tp) is Annotated:
            metadata.extend(args[1:])
            tp = args[0]
        else:
            tp = next(a for a in args if a is not type(None))
    lo = hi = None
    flat: list[Any] = []
    for meta in metadata:
        flat.extend(meta.metadata if isinstance(meta, FieldInfo) else [meta])
    for meta in flat:
        lo = getattr(meta, "min_length", None) if lo is None else lo
        hi = getattr(meta, "max_length", None) if hi is None else hi
    if lo is not None and lo == hi:
        return f"{lo} item" if lo == 1 else f"{lo} items"
    if hi is None:
        return f"at least {lo} item" + ("" if lo == 1 else "s")
    if lo is None:
        return f"at most {hi} items"
    return f"{lo} to {hi} items"
