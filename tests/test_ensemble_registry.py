"""The variable registry: declarations, Dataset building and validation."""

from __future__ import annotations

import numpy as np
import pytest
from test_runs_support import FakeScene, FakeSection, FakeSimulate, FakeStorage, fake_model
from test_runs_support import fake_solve as solve

from mcchain import status
from mcchain.ensemble import registry
from mcchain.ensemble.registry import VARIABLES, build_dataset, coerce_outputs, validate_dataset

DESIGN_VARIABLES = {
    "parameters": ("sample", "param"),
    "q_eq": ("sample", "body", "dof"),
    "joint_force_eq": ("sample", "joint", "xy"),
    "stable": ("sample",),
    "omega": ("sample", "mode"),
    "q": ("sample", "time", "body", "dof"),
    "v": ("sample", "time", "body", "dof"),
    "joint_force": ("sample", "time", "joint", "xy"),
    "contact_force": ("sample", "time", "joint"),
    "driver_torque": ("sample", "time", "driver"),
    "driver_force": ("sample", "time", "driver"),
    "constraint_error": ("sample", "time"),
    "energy": ("sample", "time"),
    # The contact law (issue 11's contract).
    "penetration": ("sample", "time", "joint"),
    "contact_mode": ("sample", "time", "joint"),
    "peak_contact_force": ("sample", "joint"),
    "impact_count": ("sample", "joint"),
    "max_penetration": ("sample", "joint"),
    "free_flight_time": ("sample", "joint"),
    "first_separation_time": ("sample", "joint"),
    "status": ("sample",),
    # Continuous peaks (issue 26: "What you write is what runs").
    "peak_joint_force": ("sample", "joint"),
    "peak_driver_torque": ("sample", "driver"),
}
EXTRAS = {
    "iterations": ("sample",),
    "mode_shape": ("sample", "mode", "body", "dof"),
    "damped_omega": ("sample", "mode"),
    "damping_ratio": ("sample", "mode"),
    "diverged_time": ("sample",),
    "singular_time": ("sample",),
    "contact_lost_time": ("sample",),
    "joint_moment_eq": ("sample", "joint"),
    "joint_moment": ("sample", "time", "joint"),
    "omega_cycle": ("sample", "phase", "mode"),
    "peak_driver_force": ("sample", "driver"),
    "solved_by": ("sample",),
    "requirement_met": ("sample", "requirement"),
}
HISTORIES = {
    "q",
    "v",
    "joint_force",
    "contact_force",
    "driver_torque",
    "driver_force",
    "constraint_error",
    "energy",
    "penetration",
    "joint_moment",
}


def scene(steps: int = 5) -> FakeScene:
    return FakeScene(
        text="",
        scene=FakeSection(),
        sample=FakeSection(),
        storage=FakeStorage(),
        fake=FakeSection(),
        simulate=FakeSimulate(1e-3 * steps, 1e-4, steps) if steps else None,
    )


def test_registry__declares_design_names_and_extras_exactly() -> None:
    assert {name: spec.dims for name, spec in VARIABLES.items()} == DESIGN_VARIABLES | EXTRAS
    for spec in VARIABLES.values():
        assert spec.dims[0] == "sample"
        assert spec.units and spec.long_name
        assert spec.dtype in registry.DTYPE_RULES
        assert spec.analysis in registry.ANALYSES


def test_registry__dtype_rules() -> None:
    for name, spec in VARIABLES.items():
        if name in HISTORIES:
            assert spec.storage_dtype("float32") == np.float32
            assert spec.storage_dtype("float64") == np.float64
        elif name in (
            "parameters",
            "q_eq",
            "joint_force_eq",
            "omega",
            "mode_shape",
            "damped_omega",
        ):
            assert spec.storage_dtype("float32") == np.float64
    assert VARIABLES["status"].storage_dtype() == np.uint32


def test_registry__by_analysis_partitions_variables() -> None:
    names = [s.name for a in registry.ANALYSES for s in registry.by_analysis(a)]
    assert sorted(names) == sorted(VARIABLES)
    assert {s.name for s in registry.by_analysis("simulate")} >= HISTORIES
    with pytest.raises(ValueError, match="analysis"):
        registry.by_analysis("bogus")


def test_build_dataset__dims_coords_dtypes_and_cf_attributes() -> None:
    model = fake_model(12).select(4, 12)
    ds = build_dataset(solve(model, scene()), model, start=4, attrs={"seed": 3})
    validate_dataset(ds, "float32")
    assert list(ds.sample.values) == list(range(4, 12))
    assert list(ds.body.values) == ["bar0", "bar1"]
    assert list(ds.dof.values) == ["x", "y", "theta"]
    assert list(ds.xy.values) == ["x", "y"]
    assert list(ds.param.values) == ["joint.J1.clearance", "body.bar0.mass"]
    assert list(ds.param_units.values) == ["m", "kg"]
    assert ds.sizes["time"] == 5 and ds.time.attrs["units"] == "s"
    assert ds.q.dtype == np.float32 and ds.q_eq.dtype == np.float64
    assert ds.omega.dtype == np.float64 and ds.stable.dtype == bool
    assert ds.status.dtype == np.uint32
    np.testing.assert_array_equal(ds.status.attrs["flag_masks"], status.FLAG_MASKS)
    assert ds.status.attrs["flag_meanings"] == status.FLAG_MEANINGS
    assert ds.omega.attrs["units"] == "rad s-1"
    np.testing.assert_array_equal(ds.parameters.values, model.parameters)
    assert ds.attrs == {"seed": 3}


def test_build_dataset__float64_histories_on_request() -> None:
    model = fake_model(3)
    ds = build_dataset(solve(model, scene()), model, history_dtype="float64")
    assert ds.q.dtype == np.float64 and ds.energy.dtype == np.float64
    validate_dataset(ds, "float64")
    with pytest.raises(ValueError, match="q: dtype float64"):
        validate_dataset(ds, "float32")


def test_build_dataset__only_what_the_solver_returned() -> None:
    model = fake_model(3)
    ds = build_dataset(solve(model, scene(steps=0)), model)
    assert "time" not in ds.dims and "q" not in ds
    assert set(ds.data_vars) == {
        "parameters",
        "status",
        "q_eq",
        "joint_force_eq",
        "iterations",
        "stable",
        "omega",
    }


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda o: o.update(bogus=o["status"]), "bogus: not a declared ensemble variable"),
        (lambda o: o.update(q_eq=o["q_eq"][:, :1]), "q_eq: dim body has size 1, expected 2"),
        (lambda o: o.update(q_eq=o["q_eq"][:, 0]), "q_eq: expected dims"),
        (lambda o: o.update(omega=o["omega"][:2]), "omega: dim sample has size 2"),
        (lambda o: o.update(status=o["status"] + 0.5), "status: integer array expected"),
        (lambda o: o.pop("status"), "status: missing"),
        (lambda o: o.update(time=np.zeros((2, 2))), "time: must be 1-D"),
        (lambda o: o.update(iterations=np.full(3, 2**40)), "iterations: values out of range"),
    ],
)
def test_build_dataset__rejects_bad_solver_output(change, message) -> None:
    model = fake_model(3)
    outputs = solve(model, scene())
    change(outputs)
    with pytest.raises(ValueError, match=message):
        build_dataset(outputs, model)


def test_coerce_outputs__rejects_bad_history_dtype() -> None:
    with pytest.raises(ValueError, match="history_dtype"):
        coerce_outputs({}, "float16")


def test_validate_dataset__names_the_bad_variable() -> None:
    model = fake_model(3)
    ds = build_dataset(solve(model, scene()), model)
    with pytest.raises(ValueError, match="omega: attribute units"):
        validate_dataset(ds.assign(omega=ds.omega.assign_attrs(units="Hz")))
    with pytest.raises(ValueError, match="q_eq: dims"):
        validate_dataset(ds.assign(q_eq=ds.q_eq.transpose("sample", "dof", "body")))
    with pytest.raises(ValueError, match="status: missing"):
        validate_dataset(ds.drop_vars("status"))


def test_param_units__from_the_path_key() -> None:
    assert registry.param_units("body.bar.mass") == "kg"
    assert registry.param_units("joint.O.points[1][0]") == "m"
    assert registry.param_units("driver.crank.omega") == "rad s-1"
    assert registry.param_units("scene.gravity[1]") == "m s-2"
    assert registry.param_units("force.tip.torque") == "N m"
    assert registry.param_units("something.else") == "1"
