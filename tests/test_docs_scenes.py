"""docs/scenes.md documents every key of the scene schema, with the schema's defaults.

Conventions the document keeps (and this test checks):

* Each section of a scene file has a level-2 heading whose first word is its TOML header in
  backticks: ``## `[scene]` ``, ``## `[[body]]` ``, ``## `[sample.vary]` ``. A section runs to
  the next level-2 heading.
* Each field of a section's model is a row of the section's key table (the first table whose
  header starts with ``key``): first cell `` `field` ``; its ``default`` cell is ``required``
  for a required field, starts with ``*`` (a sentence in italics) for a default computed from
  other values (``None`` in the model), and is otherwise a TOML value in backticks equal to
  the model's default. Its ``example`` cell is valid TOML.
* The sections of :class:`~mcchain.scene.models.Scene` are the rows of the table whose header
  starts with ``section``.
* Every value of a ``Literal`` field appears in its section as `` `"value"` ``; designs and
  simulate methods are the first cells of the tables headed ``design`` and ``method``.
* Every row of :data:`mcchain.parameters.TABLE` is a row of the table headed ``path``:
  `` `kind.<name>.key[i]` `` with its CF units and domain.
* Every ```` ```toml ```` block is valid TOML; a block with a ``[[body]]`` is a whole scene and
  loads with :func:`mcchain.scene.load_scene_text`.
"""

from __future__ import annotations

import re
import tomllib
import types
import typing
from pathlib import Path
from typing import Any

import pytest
from pydantic import BaseModel
from pydantic_core import PydanticUndefined

from mcchain.parameters import TABLE, Parameter
from mcchain.scene import load_scene_text
from mcchain.scene.models import Scene

DOC = Path(__file__).parent.parent / "docs" / "scenes.md"


# -- reading the document -------------------------------------------------------------------
def _doc() -> str:
    return DOC.read_text(encoding="utf-8")


def _sections(text: str) -> dict[str, str]:
    """Level-2 sections keyed by the backticked TOML header their heading starts with."""
    out: dict[str, str] = {}
    parts = re.split(r"^## ", text, flags=re.MULTILINE)
    for part in parts[1:]:
        m = re.match(r"`(\[\[?[a-z_.]+\]\]?)`", part)
        if m:
            out[m.group(1)] = part
    return out


def _split_row(line: str) -> list[str]:
    # cells are separated by | not escaped as \|
    cells = re.split(r"(?<!\\)\|", line.strip())
    return [c.strip() for c in cells[1:-1]]


def _tables(text: str) -> list[tuple[list[str], list[list[str]]]]:
    """Every markdown table of ``text``: (header cells, body rows)."""
    tables = []
    lines = text.splitlines()
    i = 0
    while i < len(lines):
        if lines[i].startswith("|") and i + 1 < len(lines) and lines[i + 1].startswith("|---"):
            header = _split_row(lines[i])
            rows = []
            i += 2
            while i < len(lines) and lines[i].startswith("|"):
                rows.append(_split_row(lines[i]))
                i += 1
            tables.append((header, rows))
        else:
            i += 1
    return tables


def _table(text: str, first: str) -> dict[str, dict[str, str]]:
    """The first table whose header starts with ``first``: rows by first cell, as
    {column: cell}."""
    for header, rows in _tables(text):
        if header and header[0] == first:
            return {row[0]: dict(zip(header, row, strict=True)) for row in rows}
    raise AssertionError(f"no table headed {first!r}")


# -- walking the schema ---------------------------------------------------------------------
def _nested_model(annotation: Any) -> tuple[type[BaseModel], str] | None:
    """The section model inside an annotation and how it nests: "table", "array" (a
    ``[[...]]`` list) or "map" (``dict[str, Model]``)."""
    origin = typing.get_origin(annotation)
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation, "table"
    if origin in (typing.Union, types.UnionType, typing.Annotated):
        for arg in typing.get_args(annotation):
            found = _nested_model(arg)
            if found:
                return found
    if origin is list:
        found = _nested_model(typing.get_args(annotation)[0])
        return (found[0], "array") if found else None
    if origin is dict:
        found = _nested_model(typing.get_args(annotation)[1])
        return (found[0], "map") if found else None
    return None


def _walk(model: type[BaseModel], prefix: str = "") -> list[tuple[str, type[BaseModel]]]:
    """(TOML header, model) of every section below ``model``."""
    out = []
    for name, field in model.model_fields.items():
        found = _nested_model(field.annotation)
        if found is None:
            continue
        sub, how = found
        path = f"{prefix}{name}"
        header = f"[[{path}]]" if how == "array" else f"[{path}]"
        out.append((header, sub))
        out += _walk(sub, prefix=f"{path}.")
    return out


SECTIONS = _walk(Scene)
FIELDS = [
    (header, model, name)
    for header, model in SECTIONS
    for name in model.model_fields
    if _nested_model(model.model_fields[name].annotation) is None
    or _nested_model(model.model_fields[name].annotation)[1] == "map"  # type: ignore[index]
]


def _literals(annotation: Any) -> list[str]:
    if typing.get_origin(annotation) is typing.Literal:
        return [str(v) for v in typing.get_args(annotation)]
    return [v for arg in typing.get_args(annotation) for v in _literals(arg)]


def _default(model: type[BaseModel], name: str) -> Any:
    field = model.model_fields[name]
    if field.default_factory is not None:
        return field.default_factory()  # type: ignore[call-arg]
    return field.default


# -- the tests ------------------------------------------------------------------------------
def test_docs__walk_finds_every_section() -> None:
    headers = [h for h, _ in SECTIONS]
    assert {"[scene]", "[[body]]", "[sample]", "[sample.vary]", "[simulate]"} <= set(headers)


@pytest.mark.parametrize("header", [h for h, _ in SECTIONS])
def test_docs__every_section_has_a_heading(header: str) -> None:
    assert header in _sections(_doc()), f"docs/scenes.md: no heading ## `{header}`"


@pytest.mark.parametrize("header", [h for h, _ in SECTIONS if h.count(".") == 0])
def test_docs__every_section_is_in_the_overview(header: str) -> None:
    table = _table(_doc(), "section")
    assert f"`{header}`" in table, f"docs/scenes.md: `{header}` missing from the sections table"
    name = header.strip("[]")
    required = Scene.model_fields[name].is_required()
    assert table[f"`{header}`"]["default"].startswith("required") == required


@pytest.mark.parametrize(
    ("header", "model", "name"), FIELDS, ids=[f"{h}.{n}" for h, _, n in FIELDS]
)
def test_docs__every_key_is_documented_with_its_default(
    header: str, model: type[BaseModel], name: str
) -> None:
    section = _sections(_doc()).get(header)
    assert section is not None, f"no heading ## `{header}`"
    table = _table(section, "key")
    row = table.get(f"`{name}`")
    assert row is not None, f"docs/scenes.md `{header}`: no row for key `{name}`"
    for column in ("meaning", "unit", "default", "allowed", "example"):
        assert row.get(column), f"`{header}` `{name}`: empty {column!r}"
    cell = row["default"]
    field = model.model_fields[name]
    default = _default(model, name)
    if field.is_required():
        assert cell == "required", f"`{header}` `{name}` is required; doc says {cell!r}"
    elif default is None or default is PydanticUndefined:
        assert cell.startswith("*"), f"`{header}` `{name}`: computed default, want *...*"
    else:
        m = re.fullmatch(r"`([^`]+)`", cell)
        assert m, f"`{header}` `{name}`: default cell {cell!r} is not one TOML value"
        documented = tomllib.loads(f"x = {m.group(1)}")["x"]
        assert documented == default, f"`{header}` `{name}`: doc {documented!r} != {default!r}"
        assert type(documented) is type(default) or isinstance(default, float)
    example = re.fullmatch(r"`([^`]+)`", row["example"])
    assert example, f"`{header}` `{name}`: example {row['example']!r} is not code"
    tomllib.loads(example.group(1).replace("\\|", "|"))
    for value in _literals(field.annotation):
        assert f'`"{value}"`' in section, f'`{header}` `{name}`: value "{value}" undocumented'


@pytest.mark.parametrize(
    ("header", "name", "column"),
    [("[sample]", "design", "design"), ("[simulate]", "method", "method")],
)
def test_docs__designs_and_methods_have_a_row_each(header: str, name: str, column: str) -> None:
    model = dict(SECTIONS)[header]
    table = _table(_sections(_doc())[header], column)
    values = _literals(model.model_fields[name].annotation)
    assert values
    assert {f'`"{v}"`' for v in values} == set(table), f"{header} {column} table"


_DRIVER_NAME = {"displacement0": "joint", "speed": "joint", "omega": "body", "angle0": "body"}
"""How the docs name a driver in a sampled path: by its joint (slider drivers' keys), its body
(angle drivers' keys), or either (``<name>``, the keys of both)."""


def _path_cell(row: Parameter) -> str:
    head = "scene" if row.kind == "scene" else f"{row.kind}.<{_DRIVER_NAME.get(row.key, 'name')}>"
    return (
        f"`{head}.{row.key}"
        + "".join("[i]" if k == 0 else "[j]" for k in range(len(row.shape)))
        + "`"
    )


@pytest.mark.parametrize("row", TABLE, ids=[f"{p.kind}.{p.key}" for p in TABLE])
def test_docs__every_sampled_parameter_is_listed_with_units(row: Parameter) -> None:
    table = _table(_sections(_doc())["[sample.vary]"], "path")
    cell = _path_cell(row)
    assert cell in table, f"docs/scenes.md [sample.vary]: no row {cell}"
    assert table[cell]["units"] == f"`{row.units}`"
    domain = table[cell]["domain"]
    if row.domain is None:
        assert domain == "any finite value"
    else:
        assert domain == row.domain.text.replace("0.0", "0").replace("1.0", "1")


def test_docs__no_stray_sampled_parameter() -> None:
    table = _table(_sections(_doc())["[sample.vary]"], "path")
    assert set(table) == {_path_cell(row) for row in TABLE}


def _toml_blocks() -> list[str]:
    return re.findall(r"^```toml\n(.*?)^```", _doc(), flags=re.MULTILINE | re.DOTALL)


def test_docs__has_a_whole_scene_example() -> None:
    assert any("[[body]]" in block for block in _toml_blocks())


@pytest.mark.parametrize("index", range(len(_toml_blocks())))
def test_docs__toml_blocks_parse_and_whole_scenes_load(index: int) -> None:
    block = _toml_blocks()[index]
    tomllib.loads(block)
    if "[[body]]" in block:
        scene = load_scene_text(block)
        assert scene.body
