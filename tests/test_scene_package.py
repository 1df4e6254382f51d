"""The ``mcchain.scene`` package's names, imported on first use: each is its module's own
object, and a reader of stored requirements (``scene.study``) does not load the compiler and
the other models."""

from __future__ import annotations

import importlib

import pytest
from test_cli_commands import fresh_interpreter

import mcchain.scene


@pytest.mark.parametrize("name", mcchain.scene.__all__)
def test_scene_package__every_name_is_its_module_s_object(name: str) -> None:
    value = getattr(mcchain.scene, name)
    home = importlib.import_module(f"mcchain.scene.{mcchain.scene._HOME[name]}")
    assert value is getattr(home, name)
    assert name in dir(mcchain.scene)


def test_scene_package__names_and_homes_agree_and_unknown_names_raise() -> None:
    assert sorted(mcchain.scene.__all__) == sorted(mcchain.scene._HOME)
    with pytest.raises(AttributeError, match="has no attribute 'nope'"):
        _ = mcchain.scene.nope  # type: ignore[attr-defined]


def test_scene_package__the_requirement_model_alone_loads_no_compiler() -> None:
    code = (
        "import sys\n"
        "from mcchain.scene.study import Requirement\n"
        "print(*sorted(m for m in sys.modules if m.startswith('mcchain.scene')))"
    )
    loaded = fresh_interpreter(code).split()
    assert loaded == ["mcchain.scene", "mcchain.scene.fields", "mcchain.scene.study"]
