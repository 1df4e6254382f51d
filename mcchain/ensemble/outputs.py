"""The ``[[output]]`` variables of a scene: declared by the scene, not by the registry.

Each ``[[output]]`` is a per-sample float64 variable named after it (dims ``sample``), whose
units follow its quantity (``Output.units``) and whose ``long_name`` says what it is; its
definition (the table as written, resolved) is kept in the attribute
:data:`OUTPUT_ATTRIBUTE`, so a file read back says what each output is and
:func:`mcchain.ensemble.registry.validate_dataset` knows it for one. The compiled model
carries the scene's outputs (``Model.meta["outputs"]``, set by
:func:`mcchain.scene.compile_model`), so every chunk of it knows its variables.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

from mcchain.ensemble.spec import VariableSpec

if TYPE_CHECKING:
    import xarray as xr

    from mcchain.model import Model

OUTPUT_ATTRIBUTE = "output_definition"
"""The attribute of an output variable holding its ``[[output]]`` table (JSON)."""


def output_variables(outputs: Sequence[Any]) -> dict[str, VariableSpec]:
    """The variables of ``[[output]]`` tables (:class:`mcchain.scene.outputs.Output`)."""
    specs: dict[str, VariableSpec] = {}
    for output in outputs:
        definition = json.dumps(output.model_dump(mode="json", exclude_none=True), sort_keys=True)
        specs[output.name] = VariableSpec(
            output.name,
            ("sample",),
            output.units,
            output.long_name,
            "float64",
            "equilibrium" if output.at is not None else "simulate",
            {OUTPUT_ATTRIBUTE: definition},
        )
    return specs


def model_outputs(model: Model) -> tuple[Any, ...]:
    """The ``[[output]]`` tables a compiled model carries (none for a model built
    without a scene)."""
    outputs: Any = model.meta.get("outputs", ())
    return tuple(outputs)


def model_output_variables(model: Model) -> dict[str, VariableSpec]:
    """:func:`output_variables` of the outputs ``model`` carries."""
    return output_variables(model_outputs(model))


def dataset_outputs(ds: xr.Dataset) -> list[str]:
    """The output variables of a Dataset (those with :data:`OUTPUT_ATTRIBUTE`)."""
    return [str(name) for name, var in ds.data_vars.items() if OUTPUT_ATTRIBUTE in var.attrs]


def stored_output(name: str, attrs: Mapping[str, Any]) -> VariableSpec | None:
    """The declaration of an output variable read back from a file (by its
    :data:`OUTPUT_ATTRIBUTE`), None for any other variable."""
    if OUTPUT_ATTRIBUTE not in attrs:
        return None
    units, long_name = str(attrs.get("units")), str(attrs.get("long_name"))
    return VariableSpec(name, ("sample",), units, long_name, "float64", "simulate")
