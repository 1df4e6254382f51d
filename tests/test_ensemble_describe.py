"""The ensemble describes itself: ``show`` and ``report`` rebuild the model of a run's samples
from its stored scene text and ``parameters``, never by sampling the scene again."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import xarray as xr
from test_viz_playback import read_rrd

from mcchain import cli
from mcchain.ensemble.describe import model_of_values, stored_model
from mcchain.model import JOINT_CLEARANCE, JOINT_IDEAL, PER_SAMPLE_FIELDS, Model
from mcchain.scene import compile_model, load_scene_text
from mcchain.viz import geometry, show

MAGNIFY = 100.0

# Joint O is ideal as written and a clearance joint once its clearance is sampled; the
# journal's attachment point and a spring point are sampled too, so the geometry drawn
# depends on every column.
SCENE = """\
[scene]
name = "described"

[[body]]
name = "bar"
mass = 2.0
inertia = 0.16666666666666666
position = [0.0, -0.5]
angle = -1.5707963267948966

[[joint]]
name = "O"
bodies = ["ground", "bar"]
points = [[0.0, 0.0], [-0.5, 0.0]]

[[spring]]
name = "s"
bodies = ["ground", "bar"]
points = [[0.3, 0.0], [0.5, 0.0]]
stiffness = 100.0
rest_length = 0.2

[equilibrium]

[sample]
count = 6
seed = 3
design = "lhs"
[sample.vary]
"joint.O.clearance" = { uniform = [1e-4, 1e-3] }
"joint.O.points[1][0]" = { uniform = [-0.55, -0.45] }
"spring.s.points[1][1]" = { uniform = [-0.05, 0.05] }
"""
PATHS = ("joint.O.clearance", "joint.O.points[1][0]", "spring.s.points[1][1]")
NSAMPLE = 6
# values no sampler of this scene draws (evenly spaced): what the run stored
STORED = np.column_stack(
    [
        np.linspace(2e-4, 9e-4, NSAMPLE),
        np.linspace(-0.54, -0.46, NSAMPLE),
        np.linspace(-0.04, 0.04, NSAMPLE),
    ]
)


def assert_same_model(got: Model, want: Model) -> None:
    """Every array equal, per-sample ones after broadcasting over the samples."""
    assert got.nsample == want.nsample and got.param_paths == want.param_paths
    np.testing.assert_array_equal(got.parameters, want.parameters)
    for name in ("joint_kind", "joint_row", "driver_row", "joint_body_a", "joint_body_b"):
        np.testing.assert_array_equal(getattr(got, name), getattr(want, name), err_msg=name)
    for name in sorted(PER_SAMPLE_FIELDS):
        a, b = getattr(got, name), getattr(want, name)
        shape = (want.nsample, *b.shape[1:])
        np.testing.assert_array_equal(
            np.broadcast_to(a, shape), np.broadcast_to(b, shape), err_msg=name
        )


def test_model_of_values__equals_the_compiled_model_of_the_same_values() -> None:
    compiled = compile_model(load_scene_text(SCENE))
    assert compiled.param_paths == PATHS
    rebuilt = model_of_values(SCENE, compiled.param_paths, compiled.parameters)
    assert_same_model(rebuilt, compiled)
    assert rebuilt.joint_kind.tolist() == [JOINT_CLEARANCE]


def test_model_of_values__without_parameters_is_the_nominal_scene() -> None:
    text = SCENE[: SCENE.index("[sample]")]
    nominal = compile_model(load_scene_text(text))
    assert_same_model(model_of_values(text, (), np.empty((1, 0))), nominal)
    assert nominal.joint_kind.tolist() == [JOINT_IDEAL]


def write_run(folder: Path, ids: np.ndarray | None = None) -> Path:
    """A run folder holding an equilibrium-only ensemble of ``STORED`` (samples ``ids``)."""
    ids = np.arange(NSAMPLE) if ids is None else ids
    n = len(ids)
    q_eq = np.tile([0.0, -0.5, -np.pi / 2], (n, 1, 1))
    settings = {"scene": {"sample": {"design": "lhs"}}, "samples": NSAMPLE, "seed": 3}
    ds = xr.Dataset(
        {
            "parameters": (("sample", "param"), STORED[ids]),
            "q_eq": (("sample", "body", "dof"), q_eq),
            "joint_force_eq": (("sample", "joint", "xy"), np.ones((n, 1, 2))),
            "status": (("sample",), np.zeros(n, dtype=np.uint32)),
        },
        coords={
            "sample": ids,
            "param": list(PATHS),
            "body": ["bar"],
            "dof": ["x", "y", "theta"],
            "joint": ["O"],
            "xy": ["x", "y"],
        },
        attrs={"scene": SCENE, "settings": json.dumps(settings), "seed": 3},
    )
    folder.mkdir(parents=True)
    ds.to_netcdf(folder / "ensemble.nc")
    (folder / "run.json").write_text("{}")
    return folder


def patch_sampler(monkeypatch: pytest.MonkeyPatch, sampler: Any) -> None:
    """Replace ``sample_parameters`` wherever the scene package holds it."""
    for name, module in list(sys.modules.items()):
        if name.startswith("mcchain.scene") and hasattr(module, "sample_parameters"):
            monkeypatch.setattr(module, "sample_parameters", sampler)


def raising(*args: Any, **kwargs: Any) -> np.ndarray:
    raise AssertionError("the sampler was called")


def other_numbers(sample: Any, count: int | None = None, *args: Any, **kwargs: Any) -> np.ndarray:
    n = sample.count if count is None else count
    return np.tile([5e-4, -0.5, 0.0], (n, 1))


def drawn(folder: Path) -> dict[str, np.ndarray]:
    """What ``show`` draws of each sample's mechanism, from the model it rebuilds."""
    ds, model = show.open_inputs(folder)
    out: dict[str, np.ndarray] = {}
    for s in range(NSAMPLE):
        q = ds["q_eq"].sel(sample=s).values[None]
        jt = geometry.joint_track(model, s, q, MAGNIFY)
        out[f"{s} bearing"], out[f"{s} drawn"] = jt.bearing, jt.drawn
        out[f"{s} radius"] = jt.circle_radius
        for o in geometry.body_outlines(model, s):
            out[f"{s} outline {o.name}"] = np.concatenate(o.strips)
    return out


@pytest.mark.parametrize("sampler", [raising, other_numbers], ids=["raises", "other numbers"])
def test_show__geometry_comes_from_the_stored_parameters(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, sampler: Any
) -> None:
    run = write_run(tmp_path / "run")
    before = drawn(run)
    patch_sampler(monkeypatch, sampler)
    if sampler is raising:  # the patch bites: sampling the scene now fails
        with pytest.raises(AssertionError, match="sampler was called"):
            compile_model(load_scene_text(SCENE))
    after = drawn(run)
    assert before.keys() == after.keys()
    for key in before:
        np.testing.assert_array_equal(after[key], before[key], err_msg=key)
    model = show.open_inputs(run)[1]
    np.testing.assert_array_equal(model.joint_clearance[:, 0], STORED[:, 0])
    np.testing.assert_array_equal(model.joint_point_b[:, 0, 0], STORED[:, 1])
    np.testing.assert_array_equal(model.spring_point_b[:, 0, 1], STORED[:, 2])
    np.testing.assert_array_equal(before["5 radius"], [MAGNIFY * STORED[5, 0]])


def test_show_and_report__run_with_the_sampler_gone(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    run = write_run(tmp_path / "run")
    saved = tmp_path / "before.rrd"
    assert cli.main(["show", str(run), "--samples", "1,4", "--save", str(saved)]) == 0
    patch_sampler(monkeypatch, raising)
    again = tmp_path / "after.rrd"
    assert cli.main(["show", str(run), "--samples", "1,4", "--save", str(again)]) == 0
    first, second = read_rrd(saved), read_rrd(again)
    mechanism = sorted(p for p in first if "/mechanism/" in p)
    assert "/sample/4/mechanism/clearance/bearing" in mechanism
    assert mechanism == sorted(p for p in second if "/mechanism/" in p)
    for path in mechanism:
        assert first[path].keys() == second[path].keys(), path
        for key, value in first[path].items():
            if key != "time":
                assert second[path][key] == value, (path, key)
    assert cli.main(["report", str(run), "--out", str(tmp_path / "report")]) == 0
    out = capsys.readouterr().out
    assert "skipped sobol.png: the sample design is 'lhs'" in out
    assert (tmp_path / "report" / "status_counts.png").is_file()


def test_stored_model__rows_are_global_sample_indices(tmp_path: Path) -> None:
    """An unfinished run (chunk 2:4 missing): rows of absent samples are NaN."""
    run = write_run(tmp_path / "run", ids=np.array([0, 1, 4, 5]))
    with xr.open_dataset(run / "ensemble.nc") as ds:
        model = stored_model(ds)
    assert model.nsample == NSAMPLE
    np.testing.assert_array_equal(model.joint_clearance[[0, 1, 4, 5], 0], STORED[[0, 1, 4, 5], 0])
    assert np.isnan(model.joint_clearance[2:4, 0]).all()
