"""Every kind of bad scene named by issue #2, through ``mcchain run``: one line naming the key
and the reason, exit code 2, and no run folder."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest
from test_cli_commands import Ran, assert_scene_refused

from mcchain.testing.factory import chain_scene_text, clearance_bar_text, paper_bar_text
from mcchain.testing.scenes import fourbar_text

BAR = clearance_bar_text()

SAMPLE = '\n[sample]\ncount = 10\n[sample.vary]\n"{path}" = {{ {dist} }}\n'


def _chain_with_extra_joint(points: str, bodies: str = '["ground", "b1"]') -> str:
    text = chain_scene_text(2, (), seed=2)
    if points == "same as J1":  # J1 again: two rows that repeat J1's
        block = text[text.index('name = "J1"') :]
        points = next(x for x in block.splitlines() if x.startswith("points")).split("=", 1)[1]
    return text + f'\n[[joint]]\nname = "extra"\nbodies = {bodies}\npoints = {points}\n'


CASES = {
    "malformed": ("[scene\nname = 1", "malformed TOML"),
    "unknown key": (BAR.replace("mass = 2.0", "mass = 2.0\ncolour = 1"), "body.bar.colour"),
    "missing key": (BAR.replace("mass = 2.0\n", ""), "body.bar.mass"),
    "unknown body": (BAR.replace('["ground", "bar"]', '["ground", "beam"]'), "beam"),
    "duplicate": (BAR + '[[body]]\nname = "bar"\nmass = 1.0\ninertia = 1.0\n', "duplicate"),
    "self joint": (BAR.replace('["ground", "bar"]', '["bar", "bar"]'), "joint.O.bodies"),
    "mass": (BAR.replace("mass = 2.0", "mass = 0.0"), "body.bar.mass"),
    "inertia nan": (BAR.replace("inertia = 0.16666666666666666", "inertia = nan"), "inertia"),
    "clearance": (BAR.replace("clearance = 0.001", "clearance = -0.001"), "joint.O.clearance"),
    "unknown path": (BAR + SAMPLE.format(path="body.beam.mass", dist="uniform = [1, 2]"), "beam"),
    "low > high": (BAR + SAMPLE.format(path="body.bar.mass", dist="uniform = [2, 1]"), "uniform"),
    "negative std": (BAR + SAMPLE.format(path="body.bar.mass", dist="normal = [2, -1]"), "normal"),
    "driver body": (BAR + '[[driver]]\nbody = "crank"\nomega = 1.0\n', "crank"),
    "force body": (BAR + '[[force]]\nbody = "tip"\nvalue = [1.0, 0.0]\n', "tip"),
    "spring body": (
        BAR + '[[spring]]\nbodies = ["ground", "x"]\npoints = [[0, 0], [0, 0]]\nstiffness = 1.0\n',
        "unknown body 'x'",
    ),
    "redundant": (
        _chain_with_extra_joint("same as J1", bodies='["b0", "b1"]'),
        "redundant constraints: rank of B is 4 < 6",
    ),
    "negative dof": (
        paper_bar_text()
        + '[[joint]]\nbodies = ["ground", "bar"]\npoints = [[0.0, -1.0], [0.5, 0.0]]\n'
        + '[[joint]]\nname = "C"\nbodies = ["ground", "bar"]\npoints = [[0.0, 0.0], [0.0, 0.0]]\n',
        "negative degrees of freedom",
    ),
    "unassemblable": (_chain_with_extra_joint("[[5.0, 0.0], [0.0, 0.0]]"), "cannot be assembled"),
    "body held by nothing": (
        BAR + '[[body]]\nname = "loose"\nmass = 1.0\ninertia = 0.1\n',
        "body[1]: 'loose' is not connected to the ground",
    ),
    "inertia scaled and sampled": (
        BAR.replace("mass = 2.0", "mass = 2.0\nscale_inertia = true")
        + SAMPLE.format(path="body.bar.inertia", dist="uniform = [0.1, 0.2]"),
        'body.bar.scale_inertia: the inertia is sampled as well (sample.vary."body.bar.inertia"); '
        "scale it "
        "with the mass or sample it, not both",
    ),
    "a switch written as a string": (
        BAR.replace("[modes]\n", '[modes]\nshapes = "yes"\n'),
        "modes.shapes: expected true or false, got the string 'yes'",
    ),
    "a switch written as a number": (
        BAR.replace("mass = 2.0", "mass = 2.0\nscale_inertia = 1"),
        "body.bar.scale_inertia: expected true or false, got 1",
    ),
    "loop driven twice": (
        fourbar_text() + '[[driver]]\nbody = "rocker"\nomega = 5.0\n[equilibrium]\n',
        "driver.rocker: the mechanism has 1 degree(s) of freedom (9 coordinates, 4 joints of "
        "2 rows each, clearances closed), already driven by driver.crank; one more driver "
        "over-constrains it",
    ),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_cli_run__bad_scene_is_one_line_exit_2_no_folder(
    mcchain: Callable[..., Ran], tmp_path: Path, case: str
) -> None:
    text, fragment = CASES[case]
    assert text != BAR  # the mutation applied
    assert_scene_refused(mcchain, tmp_path, text, fragment)
