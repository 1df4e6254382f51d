"""Mistakes that cost a day, each answered by one line through the command line (in process):
a clearance written in millimetres, a run larger than its disk, a disk that fills up during
the run, a run whose every sample failed, a run folder removed while the run goes, and
``show --save`` onto an existing file."""

from __future__ import annotations

import errno
import os
import shutil
from pathlib import Path
from typing import Any

import pytest
from test_cli_commands import assert_scene_refused, assert_usage_error, in_process

from mcchain.errors import SceneError
from mcchain.runner.runs import read_record
from mcchain.testing.factory import clearance_bar_text

REPO = Path(__file__).resolve().parents[1]

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


def test_units__clearances_up_to_the_share_pass() -> None:
    """25 mm on the bar (its limit), a normal whose mean + 4 std is 24 mm, a lognormal whose
    exp(mu + 4 sigma) is 24.8 mm and a choice up to 25 mm load."""
    from mcchain.scene import load_scene_text

    load_scene_text(BAR.replace("clearance = 0.001", "clearance = 0.025"))
    load_scene_text(BAR + VARY.format(dist="normal = [0.016, 0.002]"))
    load_scene_text(BAR + VARY.format(dist="lognormal = [-4.097, 0.1]"))
    load_scene_text(BAR + VARY.format(dist="choice = [1e-3, 0.025]"))
    with pytest.raises(SceneError, match=r"lognormal: exp\(mu \+ 4 sigma\) 0.0252"):
        load_scene_text(BAR + VARY.format(dist="lognormal = [-4.08, 0.1]"))


@pytest.mark.parametrize(
    ("config", "joint", "expected"),
    [
        ("fourbar-clearance", "B", (0.125, "the centre of mass of body 'rocker'")),
        ("fourbar-clearance", "O4", (0.125, "the centre of mass of body 'rocker'")),
        ("fourbar-clearance", "A", (0.05, "the centre of mass of body 'crank'")),
        # the pin sits at the slider's centre of mass: the rod's half length counts
        ("slider-crank-flores", "B", (0.06, "the centre of mass of body 'rod'")),
        ("paper-bar", "O", (0.5, "the centre of mass of body 'bar'")),
    ],
)
def test_units__neighbouring_dimension_of_the_shipped_joints(config, joint, expected) -> None:
    from mcchain.scene import load_scene
    from mcchain.scene.checks import neighbouring_dimension

    scene = load_scene(REPO / "configs" / f"{config}.toml")
    index = [j.name for j in scene.joint].index(joint)
    assert neighbouring_dimension(scene, index) == expected


def test_units__a_lone_joint_at_the_centre_of_mass_is_not_checked() -> None:
    """A disc pinned at its centre to the ground: no distance to measure a clearance by."""
    from mcchain.scene import load_scene_text
    from mcchain.scene.checks import neighbouring_dimension

    disc = BAR.replace("[-0.5, 0.0]]", "[0.0, 0.0]]").replace("[0.0, -0.501]", "[0.0, -0.001]")
    assert neighbouring_dimension(load_scene_text(disc), 0) is None
    load_scene_text(disc.replace("clearance = 0.001", "clearance = 0.5"))


# -- disk --------------------------------------------------------------------------------------

SWEEP = REPO / "configs" / "clearance-sweep.toml"
RUN_ARGS = ("--samples", "300", "--chunk-size", "100", "--quiet")
"""A statics sweep of 3 chunks: 169 bytes per sample (checked against real part files in
test_resources.py), 100 kB or so of files."""

TB = 10**12


@pytest.fixture(scope="module")
def completed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An uninterrupted run of :data:`SWEEP` with :data:`RUN_ARGS`."""
    from mcchain.runner.plan import start_run

    out = tmp_path_factory.mktemp("reference")
    return start_run(SWEEP, samples=300, chunk_size=100, out=out, progress=False).folder


@pytest.fixture(scope="module")
def reference(completed: Path) -> bytes:
    """The bytes of :func:`completed`'s ensemble.nc."""
    return (completed / "ensemble.nc").read_bytes()


class FillingDisk:
    """A file system that fills up, in process: once ``full``, writing a part file fails
    as netCDF fails on a full disk (``RuntimeError: NetCDF: HDF error``), and writing
    ``run.json`` or a line of ``run.log`` raises ``ENOSPC``; ``shutil.disk_usage`` reports
    ``free`` bytes (1 TB until full)."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch, free: int = 40_000) -> None:
        from mcchain.ensemble import io
        from mcchain.runner import resources, runs

        self.full = False
        self.free_when_full = free
        write_chunk, write_text = io._write_chunk, io.write_text_atomic

        def usage(path: Any) -> Any:
            total = 2 * TB
            free = self.free_when_full if self.full else TB
            return shutil._ntuple_diskusage(total, total - free, free)  # type: ignore[attr-defined]

        def chunk(variables: Any, path: Path) -> None:
            if self.full:
                path.write_bytes(b"\x89HDF")  # a start, then no room: the temporary is removed
                raise RuntimeError("NetCDF: HDF error")
            write_chunk(variables, path)

        def text(path: Path, content: str) -> None:
            if self.full:
                raise OSError(errno.ENOSPC, "No space left on device")
            write_text(path, content)

        disk = self

        class Stream:
            def __init__(self, stream: Any) -> None:
                self.stream = stream

            def write(self, line: str) -> int:
                if disk.full:
                    raise OSError(errno.ENOSPC, "No space left on device")
                return int(self.stream.write(line))

            def flush(self) -> None:
                if disk.full:
                    raise OSError(errno.ENOSPC, "No space left on device")
                self.stream.flush()

            def close(self) -> None:
                self.stream.close()

        opener = runs._RunLogHandler._open
        monkeypatch.setattr(resources.shutil, "disk_usage", usage)
        monkeypatch.setattr(io, "_write_chunk", chunk)
        monkeypatch.setattr(io, "write_text_atomic", text)
        monkeypatch.setattr(runs._RunLogHandler, "_open", lambda h: Stream(opener(h)))

    def fill_at_part(self, monkeypatch: pytest.MonkeyPatch, number: int) -> None:
        """The disk fills up when part file ``number`` (from 1) is written."""
        from mcchain.ensemble import io

        write_part, count = io.write_part, [0]

        def part(*args: Any, **kwargs: Any) -> Any:
            count[0] += 1
            self.full = self.full or count[0] == number
            return write_part(*args, **kwargs)

        monkeypatch.setattr(io, "write_part", part)


def assert_one_line(ran: Any, code: int, *fragments: str) -> str:
    """Exit ``code``, one line on stderr holding every fragment; the line."""
    assert ran.returncode == code, ran.stderr
    lines = ran.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("mcchain: error: "), ran.stderr
    for fragment in fragments:
        assert fragment in lines[0], lines[0]
    return str(lines[0])


def test_disk__a_run_larger_than_the_free_space_is_refused(tmp_path, monkeypatch, capsys):
    """The issue's 1e5 samples at output_dt = dt = 1e-7 (25 ms of the four-bar: 250,001
    stored times of 37 float32 values and 4 int8 each, 38 MB per sample): 3.8 TB of part
    files and as much for ensemble.nc, refused against 1 TB free, with nothing written."""
    text = (REPO / "configs" / "fourbar-clearance.toml").read_text()
    start = text.index("[simulate]")
    text = text[:start] + (
        '[simulate]\nt_end = 0.025\ndt = 1e-7\noutput_dt = 1e-7\nmethod = "rk4"\n'
        "[sample]\ncount = 100000\nseed = 1\n[sample.vary]\n"
        '"joint.B.clearance" = { uniform = [1e-4, 5e-4] }\n'
        "[storage]\nchunk_size = 1\n"  # one sample's histories in memory at a time
    )
    (tmp_path / "big.toml").write_text(text)
    FillingDisk(monkeypatch)  # 1 TB free
    ran = in_process(monkeypatch, capsys)("run", "big.toml", "--out", "runs", cwd=tmp_path)
    assert_usage_error(
        ran, "disk: the run needs up to 7.6", " TB more at its merge (part files of 100000 "
        "samples 3.8", " TB + ensemble.nc up to 3.8", "lower the count"
    )  # fmt: skip
    assert "but . has 1 TB free" in ran.stderr  # runs/ does not exist yet: its parent
    assert sorted(p.name for p in tmp_path.iterdir()) == ["big.toml"]


def test_disk__validate_prints_the_estimate(tmp_path, monkeypatch, capsys):
    ran = in_process(monkeypatch, capsys)("validate", SWEEP, cwd=tmp_path)
    assert ran.returncode == 0, ran.stderr
    # 10,000 samples of 169 B: 1.69 MB of data in 10 part files and in ensemble.nc
    assert ran.stdout.splitlines()[-1].startswith("disk: a run of 10000 samples writes up to 4."), (
        ran.stdout
    )
    assert "169 B per sample uncompressed" in ran.stdout


def test_disk__full_mid_run_is_one_line_and_resume_gives_the_same_file(
    tmp_path, monkeypatch, capsys, reference
):
    """The disk fills up at the second part file: one line naming the space needed and
    free, exit 1, no "Logging error"; the first chunk is kept, and the resume (with room)
    gives the uninterrupted run's bytes."""
    disk = FillingDisk(monkeypatch)
    disk.fill_at_part(monkeypatch, 2)
    run = in_process(monkeypatch, capsys)
    ran = run("run", SWEEP, *RUN_ARGS, "--out", "runs", cwd=tmp_path)
    (folder,) = (tmp_path / "runs").iterdir()
    name = Path("runs") / folder.name
    line = assert_one_line(ran, 1, f"{name}: the disk is full: the run still needs up to ")
    assert line.endswith(
        " and its file system has 40 kB free; 1 finished chunk kept: free space and complete "
        f"it with: mcchain run --resume {name}"
    )
    assert [p.name for p in (folder / "parts").iterdir()] == ["part-000000000000-000000000100.nc"]
    disk.full = False
    ran = run("run", "--resume", folder, "--quiet", cwd=tmp_path)
    assert ran.returncode == 0, ran.stderr
    assert (folder / "ensemble.nc").read_bytes() == reference


def test_disk__full_at_the_merge_then_a_resume_without_room_is_refused(
    tmp_path, monkeypatch, capsys, reference
):
    """Every part is written, then the merge finds no room (ENOSPC): one line, exit 1, the
    parts kept. A resume with less room than the merged file is refused before merging
    (exit 2, nothing changed); with room it gives the same bytes."""
    from mcchain.ensemble import io

    disk = FillingDisk(monkeypatch)
    merge, merges = io.merge_parts, []

    def merge_on_a_full_disk(*args: Any, **kwargs: Any) -> Any:
        merges.append(args)
        if len(merges) == 1:  # the first merge fills the disk
            disk.full = True
            raise OSError(errno.ENOSPC, "No space left on device")
        return merge(*args, **kwargs)

    monkeypatch.setattr(io, "merge_parts", merge_on_a_full_disk)
    run = in_process(monkeypatch, capsys)
    ran = run("run", SWEEP, *RUN_ARGS, "--out", "runs", cwd=tmp_path)
    (folder,) = (tmp_path / "runs").iterdir()
    assert_one_line(ran, 1, "the disk is full", "has 40 kB free; 3 finished chunks kept")
    assert "Logging error" not in ran.stderr
    before = sorted(p.name for p in (folder / "parts").iterdir())
    assert len(before) == 3
    ran = run("run", "--resume", folder, "--quiet", cwd=tmp_path)
    assert_usage_error(ran, "disk: the run needs up to ", "more at its merge (ensemble.nc up to ")
    assert ran.stderr.rstrip().endswith("has 40 kB free: free space, then resume")
    assert sorted(p.name for p in (folder / "parts").iterdir()) == before
    disk.full = False
    ran = run("run", "--resume", folder, "--quiet", cwd=tmp_path)
    assert ran.returncode == 0, ran.stderr
    assert (folder / "ensemble.nc").read_bytes() == reference


# -- every sample failed ---------------------------------------------------------------------


def test_all_failed__exit_3_with_the_status_counts_last(tmp_path, monkeypatch, capsys):
    """One Newton iteration cannot reach the tip-loaded bar's tilted equilibrium: every
    sample is flagged equilibrium_not_converged. The folder is still printed (stdout's last
    line), then the counts (stderr's one line)."""
    text = (REPO / "configs" / "clearance-bar-tip-load.toml").read_text()
    text = text.replace("[equilibrium]", "[equilibrium]\nmax_iterations = 1\n#")
    text = text.replace("[modes]", "#") + (
        '[sample]\ncount = 6\nseed = 1\n[sample.vary]\n"body.bar.mass" = { uniform = [1.9, 2.1] }\n'
    )
    (tmp_path / "stuck.toml").write_text(text)
    ran = in_process(monkeypatch, capsys)("run", "stuck.toml", "--out", "runs", cwd=tmp_path)
    (folder,) = (tmp_path / "runs").iterdir()
    assert_one_line(ran, 3, "every one of the 6 samples failed (ok 0, equilibrium_not_converged 6)")
    assert ran.stdout.splitlines()[-1] == str(Path("runs") / folder.name)


def test_all_failed__some_failures_exit_0(tmp_path, monkeypatch, capsys):
    ran = in_process(monkeypatch, capsys)(
        "run", SWEEP, "--samples", "20", "--out", "runs", "--quiet", cwd=tmp_path
    )
    assert ran.returncode == 0 and ran.stderr == "", ran.stderr


# -- the run folder removed or made unwritable -------------------------------------------------


def _at_second_part(monkeypatch: pytest.MonkeyPatch, action: Any) -> None:
    """``action(run folder)`` just before the second part file is written."""
    from mcchain.ensemble import io

    write_part, count = io.write_part, [0]

    def part(chunk: Any, directory: Path, start: int, stop: int) -> Any:
        count[0] += 1
        if count[0] == 2:
            action(Path(directory).parent)
        return write_part(chunk, directory, start, stop)

    monkeypatch.setattr(io, "write_part", part)


def test_folder_removed__one_line_naming_it_exit_1(tmp_path, monkeypatch, capsys):
    _at_second_part(monkeypatch, shutil.rmtree)
    ran = in_process(monkeypatch, capsys)("run", SWEEP, *RUN_ARGS, "--out", "runs", cwd=tmp_path)
    assert list((tmp_path / "runs").iterdir()) == []
    assert_one_line(ran, 1, "runs/", "-clearance-sweep: the run folder was removed while the run")
    assert ran.stdout == ""


def test_folder_made_unwritable__one_line_naming_it_exit_1(tmp_path, monkeypatch, capsys):
    """The folder's permission taken away (as a non-root user sees it: os.access says no and
    a new file cannot be made); its finished chunk is kept."""
    locked: list[Path] = []
    access = os.access

    def lock(folder: Path) -> None:
        locked.extend([folder.resolve(), (folder / "parts").resolve()])

    def denied(path: Any, mode: int, *args: Any, **kwargs: Any) -> bool:
        return False if Path(path).resolve() in locked else access(path, mode, *args, **kwargs)

    def chunk(variables: Any, path: Path) -> None:
        raise PermissionError(errno.EACCES, "Permission denied", str(path))

    from mcchain.ensemble import io

    write_chunk = io._write_chunk
    monkeypatch.setattr(os, "access", denied)
    monkeypatch.setattr(
        io, "_write_chunk", lambda v, p: chunk(v, p) if locked else write_chunk(v, p)
    )
    _at_second_part(monkeypatch, lock)
    ran = in_process(monkeypatch, capsys)("run", SWEEP, *RUN_ARGS, "--out", "runs", cwd=tmp_path)
    (folder,) = (tmp_path / "runs").iterdir()
    name = Path("runs") / folder.name
    line = assert_one_line(
        ran, 1, f"{name}: the run folder was made unwritable while the run went; the finished "
        f"chunks are kept: make it writable and complete it with: mcchain run --resume {name}"
    )  # fmt: skip
    assert len(list((folder / "parts").iterdir())) == 1
    record = read_record(folder)  # only os.access says no here: run.json is still written
    assert record["status"] == "FAILED" and record["error"] == line.removeprefix("mcchain: error: ")


# -- show --save onto an existing file ---------------------------------------------------------


def test_show_save__an_existing_file_is_refused_without_force(
    tmp_path, monkeypatch, capsys, completed
):
    """Refused before the run is opened, the file untouched; --force overwrites it."""
    (tmp_path / "old.rrd").write_bytes(b"an earlier recording")
    run = in_process(monkeypatch, capsys)
    ran = run("show", completed, "--samples", "0", "--save", "old.rrd", cwd=tmp_path)
    assert_usage_error(ran, "--save: old.rrd already exists (add --force to overwrite it)")
    assert (tmp_path / "old.rrd").read_bytes() == b"an earlier recording"
    ran = run("show", completed, "--samples", "0", "--save", "old.rrd", "--force", cwd=tmp_path)
    assert ran.returncode == 0 and ran.stdout == "samples 0\nold.rrd\n", ran.stderr
    assert (tmp_path / "old.rrd").read_bytes()[:4] == b"RRF2"  # a rerun recording now


def test_disk__an_extension_that_does_not_fit_is_refused(tmp_path, monkeypatch, capsys, completed):
    """``run --extend`` counts its new part files and the merged file of the total count
    (the old ensemble.nc is already on disk); refused, the run unchanged."""
    folder = tmp_path / completed.name
    shutil.copytree(completed, folder)
    before = {p.name: p.read_bytes() for p in folder.iterdir() if p.is_file()}
    disk = FillingDisk(monkeypatch)
    disk.full = True  # 40 kB free
    ran = in_process(monkeypatch, capsys)(
        "run", "--extend", folder, "--samples", "1000", "--quiet", cwd=tmp_path
    )
    assert_usage_error(
        ran, "disk: the run needs up to ", "more at its merge (part files of 1000 samples ",
        "+ ensemble.nc up to ", "has 40 kB free: free space, then extend"
    )  # fmt: skip
    assert {p.name: p.read_bytes() for p in folder.iterdir() if p.is_file()} == before
