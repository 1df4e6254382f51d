"""The parameter table: one row per (kind, key) drives paths, domains, compile, units, packing."""

from __future__ import annotations

from dataclasses import fields

import numpy as np
import pytest

from mcchain.codegen.topology import Topology, pack_parameters
from mcchain.model import (
    JOINT_CLEARANCE,
    JOINT_IDEAL,
    PER_SAMPLE_FIELDS,
    JointKind,
    KernelModel,
    Model,
)
from mcchain.parameters import (
    KINDS,
    PARAMETERS,
    TABLE,
    packed_slot_names,
    param_units,
)
from mcchain.scene import compile_model, parameter_slot, parse_path, scene_from_dict
from mcchain.scene.paths import PARAM_SHAPES, SCENE_MODELS
from mcchain.testing.factory import chain_scene_dict

U = {"uniform": [0.1, 0.2]}


def _topology(nbody: int, clearance: tuple[int, ...], **kw: object) -> Topology:
    return Topology.from_model(
        compile_model(scene_from_dict(chain_scene_dict(nbody, clearance, **kw)))
    )  # type: ignore[arg-type]


TOPOLOGIES = {
    "bar": lambda: _topology(1, ()),
    "clearance-chain": lambda: _topology(3, (0, 2), springs=2, forces=1),
    "driven-chain": lambda: _topology(4, (1,), seed=3, springs=1, forces=2, driver=True),
}


def _sizes(topo: Topology) -> tuple[tuple[int, ...], int, int, int, int]:
    return (topo.joint_kind, topo.nbody, topo.ndriver, len(topo.force_body), len(topo.spring_a))


def test_packed_slot_names__in_the_generated_kernels_order() -> None:
    """The order the generated code reads ``P`` in (its golden hashes pin it too): scene,
    bodies (plain slots, then inverses), joints (clearance only for clearance joints),
    drivers, forces, springs."""
    names = packed_slot_names((JointKind.IDEAL, JointKind.CLEARANCE), 2, 1, 1, 1)
    assert names == [
        "gx", "gy",
        "m0", "J0", "im0", "iJ0", "m1", "J1", "im1", "iJ1",
        "sax0", "say0", "sbx0", "sby0", "sax1", "say1", "sbx1", "sby1", "cl1",
        "th0_0", "om0",
        "fpx0", "fpy0", "fx0", "fy0", "tq0",
        "spax0", "spay0", "spbx0", "spby0", "k0", "l00", "cd0",
    ]  # fmt: skip


@pytest.mark.parametrize("name", sorted(TOPOLOGIES))
def test_topology_slots__are_the_tables(name: str) -> None:
    topo = TOPOLOGIES[name]()
    assert list(topo.slots()) == packed_slot_names(*_sizes(topo))


def test_pack_parameters__rows_hold_the_model_values() -> None:
    clearance = {"uniform": [1e-4, 1e-3]}  # m: U would be a clearance as large as the bars
    vary = {"body.b1.mass": U, "joint.J2.clearance": clearance, "spring.S0.damping": U}
    d = chain_scene_dict(3, (0, 2), seed=2, springs=1, forces=1, driver=True, sample=5, vary=vary)
    model = compile_model(scene_from_dict(d))
    topo = Topology.from_model(model)
    P, slot = pack_parameters(model, topo), topo.slots()
    assert P.shape == (len(slot), 5)
    np.testing.assert_array_equal(P[slot["m1"]], model.body_mass[:, 1])
    np.testing.assert_array_equal(P[slot["im1"]], 1.0 / model.body_mass[:, 1])
    np.testing.assert_array_equal(P[slot["iJ0"]], np.full(5, 1.0 / model.body_inertia[0, 0]))
    np.testing.assert_array_equal(P[slot["cl2"]], model.joint_clearance[:, 2])
    np.testing.assert_array_equal(P[slot["sbx1"]], np.full(5, model.joint_point_b[0, 1, 0]))
    np.testing.assert_array_equal(P[slot["cd0"]], model.spring_damping[:, 0])
    np.testing.assert_array_equal(P[slot["om0"]], np.full(5, model.driver_omega[0, 0]))
    assert "cl1" not in slot  # J1 is ideal: no clearance slot


def test_table__rows_unique_and_every_slot_per_element() -> None:
    assert len(PARAMETERS) == len(TABLE)
    assert KINDS == ("scene", "body", "joint", "driver", "force", "spring")
    for row in TABLE:
        assert not row.slots or len(row.slots) == row.size, row
        assert len(row.inverse_slots) in (0, row.size), row
        assert row.packed_for is None or row.kind in ("joint", "driver", "force"), row


def test_table__keys_are_scene_keys_and_fields_are_model_arrays() -> None:
    model_fields = {f.name for f in fields(Model)}
    filled: set[str] = set()
    for row in TABLE:
        *tables, key = row.key.split(".")
        scene_model = SCENE_MODELS[row.kind]
        for table in tables:  # a sub-table's key: ``contact.stiffness``
            scene_model = scene_model.model_fields[table].annotation.__args__[0]
        assert key in scene_model.model_fields, row
        names = row.field if isinstance(row.field, tuple) else (row.field,)
        assert set(names) <= model_fields & set(KernelModel._fields), row
        filled |= set(names)
    # Every per-sample Model array is filled from the table (topology arrays are not).
    assert filled == PER_SAMPLE_FIELDS


def test_table__drives_path_shapes() -> None:
    shapes = {
        (kind, key): shape for kind, keys in PARAM_SHAPES.items() for key, shape in keys.items()
    }
    assert shapes == {(row.kind, row.key): row.shape for row in TABLE}
    # Keys are listed in the order the scene file reference gives them (error messages).
    assert list(PARAM_SHAPES["driver"]) == [
        "omega", "angle0", "amplitude", "frequency", "phase", "displacement0", "speed",
    ]  # fmt: skip


@pytest.mark.parametrize("row", TABLE, ids=lambda r: f"{r.kind}.{r.key}")
def test_table__model_index_matches_compiled_value(row) -> None:
    d = chain_scene_dict(2, (1,), seed=5, springs=1, forces=1, driver=True)
    d["force"][0] |= {"torque": 0.25, "law": "harmonic", "frequency": 4.0, "phase": 0.75}
    d["joint"][1]["eccentricity"] = 0.5
    d["driver"][0] |= {"angle0": 0.125, "law": "harmonic", "amplitude": 0.25, "frequency": 2.0}
    d["driver"][0]["phase"] = 0.5
    d["spring"][0]["rest_length"] = 0.375
    d["joint"][1]["contact"] = {
        "law": "flores", "stiffness": 2e9, "exponent": 1.25, "restitution": 0.75,
        "friction": 0.125, "radius": 0.0625,
    }  # fmt: skip
    scene = scene_from_dict(d)
    model = compile_model(scene)
    item = 0 if row.kind == "scene" else 1 if row.kind in ("body", "joint") else 0
    items = [scene.scene] if row.kind == "scene" else getattr(scene, row.kind)
    written = row.scene_value(items[item])
    if written is None:  # a key of another kind of item (a slider driver's speed): unset
        written = row.unset
    np.testing.assert_array_equal(row.read(model, item), np.asarray(written, dtype=float))
    # parse_path + parameter_slot land where model_index says.
    name = (
        ""
        if row.kind == "scene"
        else f"{row.kind}." + (items[item].body if row.kind == "driver" else str(items[item].name))
    )
    for idx in row.elements:
        path = (f"scene.{row.key}" if row.kind == "scene" else f"{name}.{row.key}") + "".join(
            f"[{i}]" for i in idx
        )
        assert parameter_slot(parse_path(scene, path, PARAM_SHAPES)) == row.model_index(item, idx)


def test_param_units__every_row() -> None:
    for row in TABLE:
        head = "scene" if row.kind == "scene" else f"{row.kind}.x"
        index = "".join("[0]" for _ in row.shape)
        assert param_units(f"{head}.{row.key}{index}") == row.units


def test_joint_kind__rows_and_plain_constants() -> None:
    assert JointKind.IDEAL.rows == 2
    assert JointKind.CLEARANCE.rows == 1
    assert (JOINT_IDEAL, JOINT_CLEARANCE) == (JointKind.IDEAL, JointKind.CLEARANCE)
    assert type(JOINT_IDEAL) is int and type(JOINT_CLEARANCE) is int
