"""Mistakes that cost a day, each answered by one line through the command line (in process):
a clearance written in millimetres, a run larger than its disk, a disk that fills up during
the run, a run whose every sample failed, a run folder removed while the run goes, and
``show --save`` onto an existing file."""

from __future__ import annotations

import pytest
from test_cli_commands import assert_scene_refused, assert_usage_error, in_process

from mcchain.testing.factory import clearance_bar_text

BAR = clearance_bar_text()
VARY = '\n[sample]\ncount = 10\n[sample.vary]\n"joint.O.clearance" = {{ {dist} }}\n'
METRES = "clearances are in metres (at most 0.025 m here)"
"""The clearance bar's pin is 0.5 m from the centre of mass: 5 % of it is 25 mm."""


@pytest.mark.parametrize(
    ("text", "fragment"),
    [
        (
            BAR.replace("clearance = 0.001", "clearance = 0.5"),
            "joint.O.clearance: 0.5 m is more than 5% of the joint's shortest neighbouring "
            "dimension (0.5 m, to the centre of mass of body 'bar')",
        ),
        (
            BAR + VARY.format(dist="uniform = [0.1, 0.5]"),
            'sample.vary."joint.O.clearance".uniform: its upper bound 0.5 m is more than 5%',
        ),
        (
            BAR + VARY.format(dist="normal = [0.02, 0.002]"),
            'sample.vary."joint.O.clearance".normal: its mean + 4 standard deviations 0.028 m',
        ),
        (
            BAR + VARY.format(dist="truncnormal = [1e-3, 1e-3, 1e-4, 0.03]"),
            'sample.vary."joint.O.clearance".truncnormal: its upper bound 0.03 m',
        ),
    ],
    ids=["written", "uniform", "normal", "truncnormal"],
)
@pytest.mark.parametrize("command", ["run", "validate"])
def test_units__a_clearance_in_mm_is_one_line_exit_2(
    tmp_path, monkeypatch, capsys, command, text, fragment
):
    ran = in_process(monkeypatch, capsys)
    if command == "run":
        assert_scene_refused(ran, tmp_path, text, fragment)
        return
    (tmp_path / "scene.toml").write_text(text)
    assert_usage_error(ran("validate", "scene.toml", cwd=tmp_path), fragment, METRES)


def test_units__clearances_up_to_the_share_pass(tmp_path, monkeypatch, capsys):
    """25 mm on the bar (its limit) and a normal whose mean + 4 std is 24 mm load."""
    from mcchain.scene import load_scene_text

    load_scene_text(BAR.replace("clearance = 0.001", "clearance = 0.025"))
    load_scene_text(BAR + VARY.format(dist="normal = [0.016, 0.002]"))
