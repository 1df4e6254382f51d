"""A run folder begun by another mcchain (or under other package versions) is refused by
``--extend`` and ``--resume`` before anything is computed, in one line naming what differs.

The merge compares the study attributes of every part (the settings with every default
resolved, the software versions); a folder whose settings lack a key added since would
otherwise be refused only after its new chunks were computed ("global attributes differ"),
and its new samples would not have been computed as its old ones were.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import netCDF4
import pytest

from mcchain.cli import main
from mcchain.ensemble.study import study_differences
from mcchain.runner import plan, runs

SCENE = """
[scene]
name = "older-folder-bar"
gravity = [0.0, -9.81]
[[body]]
name = "bar"
mass = 1.0
inertia = 0.01
[[joint]]
name = "O"
bodies = ["ground", "bar"]
points = [[0.0, 0.0], [-0.5, 0.0]]
[equilibrium]
[sample]
count = 8
seed = 1
[sample.vary]
"body.bar.mass" = { uniform = [0.9, 1.1] }
"""


def folder_digest(folder: Path) -> dict[str, str]:
    return {
        str(path.relative_to(folder)): hashlib.sha256(path.read_bytes()).hexdigest()
        for path in sorted(folder.rglob("*"))
        if path.is_file()
    }


def as_if_older(path: Path) -> None:
    """Rewrite a file's attributes as a version without ``[storage] histories`` and with
    another numpy wrote them."""
    with netCDF4.Dataset(path, "a") as nc:
        settings = json.loads(nc.getncattr("settings"))
        del settings["scene"]["storage"]["histories"]
        nc.setncattr("settings", json.dumps(settings, sort_keys=True))
        versions = json.loads(nc.getncattr("versions"))
        versions["numpy"] = "1.0.0"
        nc.setncattr("versions", json.dumps(versions, sort_keys=True))


def test_study_differences__names_keys_of_the_settings_and_versions() -> None:
    ours = {
        "scene": "text",
        "sample_count": 8,
        "settings": json.dumps({"samples": 8, "scene": {"a": 1, "b": True}}),
        "versions": json.dumps({"numpy": "2.0"}),
        "kernel_compiler": "numba",
    }
    same = dict(ours, sample_count=16, kernel_compiler="interpreted")
    assert study_differences(ours, same) == []  # the count and the session are not the study
    theirs = dict(
        ours,
        settings=json.dumps({"samples": 4, "scene": {"a": 1}}),
        versions=json.dumps({"numpy": "1.0"}),
    )
    assert study_differences(ours, theirs) == [
        "settings.scene.b: absent there, true here",
        'versions.numpy: "1.0" there, "2.0" here',
    ]
    many = dict(ours, settings=json.dumps({"scene": {f"k{i}": i for i in range(9)}}))
    phrases = study_differences(ours, many, most=3)
    assert len(phrases) == 4 and phrases[-1] == "8 more"


def test_extend__a_folder_of_another_version_is_refused_before_anything_runs(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    scene = tmp_path / "bar.toml"
    scene.write_text(SCENE, encoding="utf-8")
    folder = plan.start_run(scene, run_dir=tmp_path / "run", progress=False).folder
    as_if_older(folder / runs.ENSEMBLE)
    before = folder_digest(folder)
    assert main(["run", "--extend", str(folder), "--samples", "8"]) == 2
    out, err = capsys.readouterr()
    assert out == ""
    assert len(err.strip().splitlines()) == 1, err
    assert err.startswith(f"mcchain: error: --extend: {folder.name} was written by another")
    assert 'settings.scene.storage.histories: absent there, "all" here' in err
    assert 'versions.numpy: "1.0.0" there' in err
    assert folder_digest(folder) == before  # nothing computed, nothing written


def test_resume__parts_of_another_version_are_refused_before_anything_runs(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    scene = tmp_path / "bar.toml"
    scene.write_text(SCENE, encoding="utf-8")
    calls = []

    def failing_solve(model, scene):  # type: ignore[no-untyped-def]
        from mcchain.solvers import solve_chunk

        calls.append(model.nsample)
        if calls.count(4) == 2:  # the second chunk (not the warm-up) fails: one part kept
            raise RuntimeError("power cut")
        return solve_chunk(model, scene)

    with pytest.raises(RuntimeError, match="power cut"):
        plan.start_run(
            scene, run_dir=tmp_path / "run", chunk_size=4, solve=failing_solve, progress=False
        )
    (part,) = (tmp_path / "run").rglob("part-*.nc")
    folder = part.parent.parent
    as_if_older(part)
    before = folder_digest(folder)
    assert main(["run", "--resume", str(folder)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"mcchain: error: --resume: {folder.name} was written by another")
    assert folder_digest(folder) == before
