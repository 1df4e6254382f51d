"""``[[output]]`` as a user writes it: the keys refused in one line (exit 2, nothing
written), the variables an output makes (units, long_name, its definition), requirements on
them, the CSV column, and a scene without outputs left as it was."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from test_cli_commands import Ran, assert_scene_refused

from mcchain.decision.requirements import produced_outputs
from mcchain.ensemble.outputs import OUTPUT_ATTRIBUTE, dataset_outputs, output_variables
from mcchain.ensemble.registry import build_dataset, validate_dataset
from mcchain.errors import SceneError
from mcchain.scene import compile_model, load_scene_text
from mcchain.testing.slider_crank import slider_crank_scene

SIMULATE = 't_end = 0.004\ndt = 1e-5\noutput_dt = 1e-4\nmethod = "rk4"'
BASE = slider_crank_scene(5e-4, 150.0, 0.3, SIMULATE)
OUT = '\n[[output]]\nname = "e"\n{keys}\n'
SLIDER_X = 'of = "position"\nbody = "slider"\ncomponent = "x"\n'

BAD_OUTPUTS = {
    "name": (OUT.replace('"e"', '"Slider Error"').format(keys=SLIDER_X + 'reduce = "max"'),
             "output[0].name: invalid output name 'Slider Error'"),
    "built-in name": (OUT.replace('"e"', '"omega"').format(keys=SLIDER_X + 'reduce = "max"'),
                      "output.omega.name: 'omega' is a built-in ensemble variable"),
    "duplicate": (OUT.format(keys=SLIDER_X + 'reduce = "max"') * 2,
                  "output[1].name: duplicate output name 'e'"),
    "unknown of": (OUT.format(keys='of = "jerk"\nbody = "slider"\nreduce = "max"'),
                   "output.e.of: must be one of"),
    "unknown body": (OUT.format(keys=SLIDER_X.replace('"slider"', '"piston"') + 'reduce = "max"'),
                     "output.e.body: unknown body 'piston' (known: crank, rod, slider)"),
    "no body": (OUT.format(keys='of = "angle"\nreduce = "max"'),
                "output.e.body: missing: a angle output names its body"),
    "point on a joint": (
        OUT.format(keys='of = "joint_force"\njoint = "B"\npoint = [0.0, 0.0]\n'
                        'component = "x"\nreduce = "max"'),
        "output.e.point: a joint_force output names a `joint`",
    ),
    "point of an angle": (OUT.format(keys='of = "angle"\nbody = "rod"\npoint = [0.1, 0.0]\n'
                                          'reduce = "max"'),
                          "output.e.point: a body's angle is not a point's"),
    "unknown joint": (OUT.format(keys='of = "contact_force"\njoint = "Q"\nreduce = "max"'),
                      "output.e.joint: unknown joint 'Q' (known: O, A, B, P)"),
    "contact force of an ideal joint": (
        OUT.format(keys='of = "contact_force"\njoint = "A"\nreduce = "max"'),
        "output.e.joint: joint 'A' has no clearance: no normal force",
    ),
    "penetration on the link": (
        OUT.format(keys='of = "penetration"\njoint = "B"\nreduce = "max"'),
        "output.e.joint: joint 'B' has no contact law",
    ),
    "torque of a slider driver": (
        OUT.format(keys='of = "driver_force"\ndriver = "crank"\nreduce = "max"'),
        "output.e.of: driver 'crank' turns a body: it applies a torque",
    ),
    "unknown driver": (OUT.format(keys='of = "driver_torque"\ndriver = "rod"\nreduce = "max"'),
                       "output.e.driver: unknown driver 'rod' (known: crank)"),
    "component missing": (OUT.format(keys='of = "position"\nbody = "rod"\nreduce = "max"'),
                          "output.e.component: missing: position is a vector"),
    "component of a scalar": (
        OUT.format(keys='of = "angle"\nbody = "rod"\ncomponent = "x"\nreduce = "max"'),
        "output.e.component: angle is a scalar",
    ),
    "no reduce": (OUT.format(keys=SLIDER_X), 'output.e.reduce: missing: give `reduce` or `at'),
    "threshold missing": (OUT.format(keys=SLIDER_X + 'reduce = "first_time_above"'),
                          "output.e.threshold: missing: first_time_above needs a threshold"),
    "threshold extra": (OUT.format(keys=SLIDER_X + 'reduce = "max"\nthreshold = 0.1'),
                        "output.e.threshold: only first_time_above and first_time_below"),
    "window inverted": (OUT.format(keys=SLIDER_X + 'reduce = "max"\nwindow = [0.003, 0.001]'),
                        "output.e.window: expected [start, end] with 0 <= start < end"),
    "window after the run": (
        OUT.format(keys=SLIDER_X + 'reduce = "max"\nwindow = [0.001, 0.01]'),
        "output.e.window: ends at 0.01 s, after simulate.t_end (0.004 s)",
    ),
    "window and cycles": (
        OUT.format(keys=SLIDER_X + 'reduce = "max"\nwindow = [0.0, 0.001]\ncycles = [0, 0.01]'),
        "output.e.cycles: give `window` or `cycles`, not both",
    ),
    "cycles after the run": (
        OUT.format(keys=SLIDER_X + 'reduce = "max"\ncycles = [0, 1]'),
        "output.e.cycles: turn 1.0 of driver.crank ends at t = 0.0418879 s, after",
    ),
    "at without equilibrium": (OUT.format(keys=SLIDER_X + 'at = "equilibrium"'),
                               "output.e.at: needs [equilibrium] (or [modes])"),
    "at and reduce": (OUT.format(keys=SLIDER_X + 'at = "equilibrium"\nreduce = "max"'),
                      "output.e.reduce: an output is reduced over time or `at` one state"),
    "relative contact force": (
        OUT.format(keys='of = "contact_force"\njoint = "B"\nreduce = "max"\n'
                        'relative_to = "ideal"'),
        "output.e.relative_to: an ideal joint has no contact force",
    ),
    "relative without clearance": (
        OUT.format(keys=SLIDER_X + 'reduce = "max"\nrelative_to = "ideal"'),
        "output.e.relative_to: the scene has no clearance joint",
    ),
    "unknown key": (OUT.format(keys=SLIDER_X + 'reduce = "max"\nrelative = "ideal"'),
                    "output.e.relative: unknown key (did you mean `relative_to`?"),
}  # fmt: skip


@pytest.mark.parametrize("case", sorted(BAD_OUTPUTS))
def test_output__bad_keys_one_line_exit_2_nothing_written(
    mcchain: Callable[..., Ran], tmp_path: Path, case: str
) -> None:
    extra, fragment = BAD_OUTPUTS[case]
    base = BASE.replace("clearance = 0.0005", "") if "without clearance" in case else BASE
    assert_scene_refused(mcchain, tmp_path, base + extra, fragment)


def test_output__cycles_ending_after_the_run_in_one_sample_is_refused() -> None:
    """A sampled speed moves the end of a ``cycles`` window: every sample is checked."""
    text = BASE.replace("t_end = 0.004", "t_end = 0.05") + OUT.format(
        keys=SLIDER_X + 'reduce = "max"\ncycles = [0, 1]'
    )
    compile_model(load_scene_text(text))  # 1 turn = 41.9 ms at 150 rad/s: inside
    text += (
        '[sample]\ncount = 64\n[sample.vary]\n"driver.crank.omega" = { uniform = [100.0, 200.0] }\n'
    )
    with pytest.raises(SceneError, match=r"output\.e\.cycles: turn 1\.0 of driver\.crank ends at "
                                         r"t = .* s in sample \d+ \(omega .* rad/s\), after "
                                         r"simulate\.t_end \(0\.05 s\)"):  # fmt: skip
        compile_model(load_scene_text(text))


OUTPUTS = (
    OUT.format(keys=SLIDER_X + 'reduce = "max_abs"\nrelative_to = "ideal"')
    + OUT.replace('"e"', '"t_fast"').format(
        keys='of = "angular_velocity"\nbody = "rod"\nreduce = "first_time_above"\nthreshold = 80.0'
    )
    + OUT.replace('"e"', '"sag"').format(keys=SLIDER_X + 'at = "equilibrium"')
    + "\n[equilibrium]\n"
)


def test_output__variables_units_and_definition() -> None:
    scene = load_scene_text(BASE + OUTPUTS)
    specs = output_variables(scene.output)
    assert [s.units for s in specs.values()] == ["m", "s", "m"]
    assert specs["e"].long_name == (
        "max_abs of the x of the position of the centre of mass of slider minus the ideal "
        "mechanism's over the run, continuous"
    )
    assert specs["sag"].analysis == "equilibrium"
    model = compile_model(scene)
    dims = produced_outputs(scene, model)
    assert dims["e"] == dims["t_fast"] == dims["sag"] == ("sample",)
    n = model.nsample
    data = {"status": np.zeros(n, np.uint32), "e": np.ones(n), "t_fast": np.full(n, np.inf),
            "sag": np.zeros(n)}  # fmt: skip
    ds = build_dataset(data, model, history_dtype="float32")
    validate_dataset(ds, "float32")
    assert sorted(dataset_outputs(ds)) == ["e", "sag", "t_fast"]
    assert ds["e"].attrs["units"] == "m" and OUTPUT_ATTRIBUTE in ds["e"].attrs
    assert ds["t_fast"].dtype == np.float64
    with pytest.raises(ValueError, match="e: not a declared ensemble variable"):
        build_dataset(data, compile_model(load_scene_text(BASE)))  # a model without them


def test_output__requirement_on_an_output_and_the_csv_column(
    mcchain: Callable[..., Ran], tmp_path: Path
) -> None:
    requirement = '\n[[requirement]]\nname = "accuracy"\noutput = "e"\nmax = 4.0e-4\n'
    (tmp_path / "scene.toml").write_text(BASE + OUTPUTS + requirement)
    ran = mcchain("run", "scene.toml", "--run-dir", "run", "--quiet", cwd=tmp_path)
    assert ran.returncode == 0, ran.stderr
    assert mcchain("export", "run", "--csv", cwd=tmp_path).returncode == 0
    import pandas as pd
    import xarray as xr

    table = pd.read_csv(tmp_path / "run" / "export" / "samples.csv")
    with xr.open_dataset(tmp_path / "run" / "ensemble.nc") as ds:
        assert table["e [m]"].to_numpy() == pytest.approx(ds["e"].values, rel=1e-15)
        met = ds["requirement_met"].values[:, 0]
        assert met[0] == float(ds["e"].values[0] <= 4.0e-4)
        assert 1e-4 < float(ds["e"].values[0]) < 1e-3  # of the size of the clearance
        assert np.isinf(ds["t_fast"].values[0]) or ds["t_fast"].values[0] < 0.004
        assert ds.attrs["scene_name"] == "slider-crank-link"  # global attributes kept
    # mcchain check re-solves the output, tighter, and compares it
    assert mcchain("check", "run", "--tighten", "2", "--samples", "1", cwd=tmp_path).returncode in (
        0,
        1,
    )
    with xr.open_dataset(tmp_path / "run" / "check" / "tighten-2.nc") as tight:
        assert "e" in tight.data_vars
        with xr.open_dataset(tmp_path / "run" / "ensemble.nc") as ds:
            run_value = float(ds["e"].values[0])
        assert float(tight["e"].values[0]) == pytest.approx(run_value, abs=1e-9)  # dt / 2


def test_output__a_requirement_on_an_output_the_scene_lacks_is_refused(
    mcchain: Callable[..., Ran], tmp_path: Path
) -> None:
    requirement = '\n[[requirement]]\nname = "a"\noutput = "slider_error"\nmax = 1.0\n'
    assert_scene_refused(
        mcchain, tmp_path, BASE + OUTPUTS + requirement,
        "requirement.a.output: 'slider_error' is not a per-sample variable this scene produces",
    )  # fmt: skip


def test_output__an_ideal_mechanism_that_cannot_be_built_is_refused(
    mcchain: Callable[..., Ran], tmp_path: Path
) -> None:
    """A bar between two ground pins holds only thanks to the play of one of them: ideal,
    its four rows over-constrain three coordinates."""
    text = """
[[body]]
name = "bar"
mass = 1.0
inertia = 0.08
position = [0.5, 0.0]
[[joint]]
name = "O"
bodies = ["ground", "bar"]
points = [[0.0, 0.0], [-0.5, 0.0]]
[[joint]]
name = "B"
bodies = ["ground", "bar"]
points = [[1.0, 0.001], [0.5, 0.0]]
clearance = 1e-3
[simulate]
t_end = 0.01
dt = 1e-4
[[output]]
name = "e"
of = "angle"
body = "bar"
relative_to = "ideal"
reduce = "max"
"""
    assert_scene_refused(
        mcchain, tmp_path, text,
        "output.e.relative_to: the ideal mechanism (every clearance joint ideal) cannot be "
        "built: joint: negative degrees of freedom",
    )  # fmt: skip
