"""Scenes: TOML file -> validated :class:`Scene` -> compiled :class:`~mcchain.model.Model`.

``models`` (the pydantic models), ``paths`` (parameter paths), ``checks`` (cross-references),
``messages`` (one-line errors), ``loading`` (file/text/dict in), ``sampling`` (designs and
distributions), ``compile`` (scene -> Model).

``load_scene(path)`` reads and checks a scene file and raises
:class:`~mcchain.errors.SceneError` with one line ``key.path: reason``;
``compile_model(scene, nsample, seed)`` draws the ``[sample]`` parameters and lays the scene
out as the flat arrays the kernels read. This package never imports numba or the kernels.

Its names are imported on first use (as :mod:`mcchain`'s own): a reader of a run's stored
requirements needs ``study``'s model alone, not the scene compiler and every model with it
(benchmarks/results/verdict/verdict.md).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from mcchain.scene.compile import compile_model
    from mcchain.scene.fields import GROUND_NAME
    from mcchain.scene.loading import load_scene, load_scene_text, scene_from_dict
    from mcchain.scene.mechanism import Body, Driver, Force, Joint, SceneSection, Spring
    from mcchain.scene.models import Equilibrium, Modes, Scene, Simulate, Storage
    from mcchain.scene.paths import ParamRef, parameter_slot, parse_path
    from mcchain.scene.sampling import philox_uniform, ppf, sample_parameters, unit_design
    from mcchain.scene.study import Distribution, Sample

_HOMES = {
    "compile": ("compile_model",),
    "fields": ("GROUND_NAME",),
    "loading": ("load_scene", "load_scene_text", "scene_from_dict"),
    "mechanism": ("Body", "Driver", "Force", "Joint", "SceneSection", "Spring"),
    "models": ("Equilibrium", "Modes", "Scene", "Simulate", "Storage"),
    "paths": ("ParamRef", "parameter_slot", "parse_path"),
    "sampling": ("philox_uniform", "ppf", "sample_parameters", "unit_design"),
    "study": ("Distribution", "Sample"),
}
_HOME = {name: module for module, names in _HOMES.items() for name in names}

__all__ = [
    "GROUND_NAME",
    "Body",
    "Distribution",
    "Driver",
    "Equilibrium",
    "Force",
    "Joint",
    "Modes",
    "ParamRef",
    "Sample",
    "Scene",
    "SceneSection",
    "Simulate",
    "Spring",
    "Storage",
    "compile_model",
    "load_scene",
    "load_scene_text",
    "parameter_slot",
    "parse_path",
    "philox_uniform",
    "ppf",
    "sample_parameters",
    "scene_from_dict",
    "unit_design",
]


def __getattr__(name: str) -> Any:
    """``name`` from its module, imported now (then bound here: a second use is a lookup)."""
    module = _HOME.get(name)
    if module is None:
        raise AttributeError(f"module 'mcchain.scene' has no attribute {name!r}")
    value = getattr(importlib.import_module(f"mcchain.scene.{module}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
