"""A cache folder that cannot be written never stops mcchain: one warning line, and the
kernels are cached in the temporary folder instead."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from numba import config

from mcchain import folders
from mcchain.codegen.cache import cache_dir
from mcchain.compiled import caches
from mcchain.kernels.config import ensure_numba_cache

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture
def blocked(tmp_path: Path) -> Path:
    """A folder path that cannot be made, for any user: its parent is a regular file."""
    (tmp_path / "a-file").write_text("")
    return tmp_path / "a-file" / "cache"


@pytest.fixture(autouse=True)
def fresh_warnings(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(folders, "_warned", set())


def test_writable__a_folder_under_a_file_is_not(blocked: Path, tmp_path: Path) -> None:
    assert not folders.writable(blocked)
    assert folders.writable(tmp_path / "new" / "folder")


def test_numba_cache__unwritable_dir_moves_to_temp_with_one_warning(
    blocked: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr(config, "CACHE_DIR", str(blocked))
    where = ensure_numba_cache()
    ensure_numba_cache()  # warned once only
    err = capsys.readouterr().err.splitlines()
    assert where == config.CACHE_DIR == str(folders.temporary_cache("numba"))
    assert len(err) == 1
    assert err[0].startswith(f"mcchain: warning: NUMBA_CACHE_DIR {blocked} cannot be written")


def test_numba_cache__writable_dir_is_kept_silently(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr(config, "CACHE_DIR", str(tmp_path / "numba"))
    assert ensure_numba_cache() == str(tmp_path / "numba")
    assert capsys.readouterr().err == ""


def test_generated_cache__unwritable_dir_moves_to_temp_with_one_warning(
    blocked: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setenv("MCCHAIN_CACHE_DIR", str(blocked))
    assert cache_dir() == folders.temporary_cache("generated")
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and "MCCHAIN_CACHE_DIR" in err[0]


def test_import__kernels_load_with_unwritable_caches(blocked: Path) -> None:
    """A fresh process whose caches cannot be written imports and decorates every kernel."""
    env = {
        **os.environ,
        "NUMBA_CACHE_DIR": str(blocked / "numba"),
        "MCCHAIN_CACHE_DIR": str(blocked / "mcchain"),
        "PYTHONPATH": str(REPO),
    }
    code = "import mcchain.kernels.statics, mcchain.kernels.implicit; print('ok')"
    proc = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=False
    )
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout == "ok\n"
    lines = proc.stderr.splitlines()
    assert len(lines) == 1 and "NUMBA_CACHE_DIR" in lines[0], proc.stderr


def test_designs__a_rerun_reads_the_same_points_without_importing_scipy_stats(
    tmp_path: Path,
) -> None:
    """Quasi-random designs (Sobol', LHS, Saltelli) are kept in mcchain's cache: a second
    process draws bit-identical points and never imports scipy.stats (about 1 s of a warm
    run); an unwritable cache only costs that import."""
    code = (
        "import sys, numpy as np\n"
        "from mcchain.scene.sampling import unit_design\n"
        "u = [unit_design(d, 3, 40, 7, 5, 35) for d in ('sobol', 'lhs', 'saltelli')]\n"
        "np.save(sys.argv[1], np.stack(u))\n"
        "print('scipy.stats' in sys.modules)\n"
    )

    def draw(cache: Path, name: str) -> tuple[str, np.ndarray]:
        scratch = tmp_path / f"tmp-{name}"  # the fallback of an unwritable cache: fresh
        scratch.mkdir()
        env = {
            **os.environ, "MCCHAIN_CACHE_DIR": str(cache), "PYTHONPATH": str(REPO),
            "TMPDIR": str(scratch),
        }  # fmt: skip
        out = tmp_path / f"{name}.npy"
        proc = subprocess.run(
            [sys.executable, "-c", code, str(out)], env=env, capture_output=True, text=True,
            check=True,
        )  # fmt: skip
        return proc.stdout.strip(), np.load(out)

    first, drawn = draw(tmp_path / "cache", "first")
    again, read = draw(tmp_path / "cache", "again")
    assert (first, again) == ("True", "False")
    np.testing.assert_array_equal(read, drawn)
    (tmp_path / "a-file").write_text("")
    blocked_first, unwritable = draw(tmp_path / "a-file" / "cache", "blocked")
    assert blocked_first == "True"
    np.testing.assert_array_equal(unwritable, drawn)


@pytest.fixture
def own_tmp(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A temporary folder of this test's own (``tempfile.gettempdir()``), empty."""
    import tempfile

    folder = tmp_path / "tmp"
    folder.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(folder))
    monkeypatch.setattr(folders, "_fresh", {})
    return folder


def test_temporary_cache__made_private(own_tmp: Path, capsys: pytest.CaptureFixture[str]) -> None:
    folder = folders.temporary_cache("native")
    assert folder == own_tmp / f"mcchain-native-{os.getuid()}"
    assert folder.stat().st_mode & 0o777 == 0o700
    assert folders.temporary_cache("native") == folder and capsys.readouterr().err == ""


@pytest.mark.parametrize("other", ["mode", "owner", "link"])
def test_temporary_cache__a_folder_made_before_by_another_user_is_not_used(
    own_tmp: Path, other: str, capsys: pytest.CaptureFixture[str]
) -> None:
    """The predictable folder exists already, writable by all (any user can test that), owned
    by another user (root can), or a link to another folder: a planted cache file in it is
    never read; a fresh private folder takes its place for this process, with one warning."""
    planted = own_tmp / f"mcchain-native-{os.getuid()}"
    if other == "link":
        (own_tmp / "elsewhere").mkdir(mode=0o700)
        planted.symlink_to(own_tmp / "elsewhere")
    else:
        planted.mkdir()
        planted.chmod(0o777 if other == "mode" else 0o700)
    if other == "owner":
        if os.getuid() != 0:
            pytest.skip("only root can give a folder to another user")  # "mode" covers it
        os.chown(planted, 65534, 65534)
    (planted / "mcchain_gen-accel-0.bin").write_bytes(b"planted")
    folder = folders.temporary_cache("native")
    assert folder != planted and folder.parent == own_tmp
    assert folder.name.startswith(f"mcchain-native-{os.getuid()}-")
    assert folder.stat().st_mode & 0o777 == 0o700 and not any(folder.iterdir())
    assert folders.temporary_cache("native") == folder  # the same one for the process
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and str(planted) in err[0] and "is not private" in err[0]
    reason = {"mode": "mode 0777", "owner": "owned by uid 65534", "link": "symbolic link"}
    assert reason[other] in err[0]


def test_suite__caches_in_a_temporary_folder_unless_told(tmp_path_factory) -> None:
    """tests/conftest.py: no test writes to the developer's ~/.cache/mcchain."""
    root = Path(os.environ["MCCHAIN_CACHE_DIR"])
    home = Path(os.path.expanduser("~")) / ".cache" / "mcchain"
    assert root.resolve() != home.resolve()
    assert caches.mcchain_cache("native").parent == root


# -- mcchain cache status | warm | clear (issue 29) -------------------------------------------

COUNT_RUN = """
import json, sys
from numba.core import event
from mcchain.cli import main
from mcchain.codegen import native
with event.install_recorder("numba:compile") as recorder:
    code = main(["run", sys.argv[1], "--samples", "4", "--quiet", "--run-dir", sys.argv[2]])
starts = [ev for _, ev in recorder.buffer if ev.is_start]
print(json.dumps({"code": code, "numba": len(starts), "native": native.COUNTS}))
"""


@pytest.mark.slow
def test_cache_warm__the_scenes_run_then_compiles_nothing(tmp_path: Path) -> None:
    """``mcchain cache warm`` in one process; then the scene's run in a fresh one: numba
    compiles nothing ("numba:compile" events counted) and every lane entry point is loaded
    from the cache (counted), none compiled. The run records what compiled its kernels."""
    import json

    from mcchain.runner.runs import read_record

    scene = REPO / "configs" / "double-pendulum.toml"
    env = {**os.environ, "PYTHONPATH": str(REPO), "MCCHAIN_CACHE_DIR": str(tmp_path / "cache")}
    env.pop("MCCHAIN_LANE_COMPILER", None)
    warm = subprocess.run(
        [sys.executable, "-m", "mcchain.cli", "cache", "warm", str(scene)],
        env=env, capture_output=True, text=True, timeout=1200,
    )  # fmt: skip
    assert warm.returncode == 0, warm.stderr[-3000:]
    assert warm.stdout.startswith(f"{scene}: ready in ")
    assert " compiled, 0 loaded from the cache)" in warm.stdout
    run = subprocess.run(
        [sys.executable, "-c", COUNT_RUN, str(scene), str(tmp_path / "run")],
        env=env, capture_output=True, text=True, timeout=1200,
    )  # fmt: skip
    assert run.returncode == 0, run.stderr[-3000:]
    counts = json.loads(run.stdout.splitlines()[-1])
    assert counts["code"] == 0 and counts["numba"] == 0
    assert counts["native"]["compiled"] == 0 and counts["native"]["loaded"] >= 1
    session = read_record(tmp_path / "run")["sessions"][-1]
    assert session["kernel_compiler"] == "native"
    from mcchain.codegen.layout import LMAX, target_cpu

    assert session["kernel_target"]["cpu"] == target_cpu()[0]
    assert session["kernel_target"]["lane_width"] == LMAX
    import netCDF4

    with netCDF4.Dataset(tmp_path / "run" / "ensemble.nc") as nc:
        assert nc.getncattr("kernel_compiler") == "native"


def test_cache_status_and_clear(tmp_path: Path, monkeypatch, mcchain) -> None:
    """status: each folder with its files and size, the lane entries by variant, the keys;
    clear: every cached file of mcchain's and numba's files of mcchain's kernels, nothing
    else (a .pyc beside them stays)."""
    monkeypatch.setenv("MCCHAIN_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "numba"))
    native = caches.mcchain_cache("native")
    digest = "0123456789abcdef0123"
    (native / f"mcchain_gen_rk45_{digest}-adaptive_run-abc.bin").write_bytes(b"x" * 2000)
    (native / f"mcchain_gen_rk45_{digest}-adaptive_run-def.bin").write_bytes(b"x" * 1000)
    (caches.mcchain_cache("generated") / "mcchain_gen_x.py").write_text("x = 1\n")
    (caches.mcchain_cache("lane-text") / "mcchain_gen_rk45-0123.txt").write_text("x = 1\n")
    numba_folder = caches.numba_index_folder()
    assert numba_folder is not None
    numba_folder.mkdir(parents=True)
    for name in ("statics.equilibrium_batch-10.py311.nbi", "statics.x.nbc", "other.pyc"):
        (numba_folder / name).write_bytes(b"y" * 100)
    status = mcchain("cache", "status", cwd=tmp_path)
    assert status.returncode == 0, status.stderr
    lines = status.stdout.splitlines()
    assert f"native: {native} (2 files, 0.0 MB)" in lines
    assert "  rk45.adaptive_run: 2 compiled (scenes × argument types)" in lines
    assert any(line.startswith("keyed by: native ") and "numpy " in line for line in lines)
    assert f"numba (mcchain's kernels): {numba_folder} (2 files, 0.0 MB)" in lines
    cleared = mcchain("cache", "clear", cwd=tmp_path)
    assert cleared.returncode == 0, cleared.stderr
    assert f"native: removed 2 files, 0.0 MB from {native}" in cleared.stdout.splitlines()
    assert not any(native.iterdir()) and not any(caches.mcchain_cache("generated").iterdir())
    assert not any(caches.mcchain_cache("lane-text").iterdir())
    assert [p.name for p in numba_folder.iterdir()] == ["other.pyc"]


def test_cache_warm__a_bad_scene_is_one_line_and_compiles_nothing(tmp_path: Path, mcchain):
    from test_cli_commands import assert_usage_error

    (tmp_path / "bad.toml").write_text("[scene]\nname = 3\n")
    assert_usage_error(mcchain("cache", "warm", "bad.toml", cwd=tmp_path), "scene.name")
    assert_usage_error(mcchain("cache", cwd=tmp_path), "{status,warm,clear}")


def test_generated_text__made_once_then_read_and_remade_for_another_key_or_source(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A second call reads the text the first made (make is not called); another key, or
    mcchain's sources edited (another digest), make it again; a file of the cache that
    cannot be decoded is made again too."""
    monkeypatch.setenv("MCCHAIN_CACHE_DIR", str(tmp_path))
    made: list[str] = []

    def make(text: str):
        return lambda: made.append(text) or text

    assert caches.generated_text("gen", "key a", make("A")) == "A"
    assert caches.generated_text("gen", "key a", make("stale")) == "A"
    assert made == ["A"]
    assert caches.generated_text("gen", "key b", make("B")) == "B"
    monkeypatch.setattr(caches, "sources_digest", lambda: "an edited source")
    assert caches.generated_text("gen", "key a", make("A2")) == "A2"
    assert made == ["A", "B", "A2"]
    files = sorted((tmp_path / "lane-text").iterdir())
    assert len(files) == 3 and all(p.name.startswith("gen-") for p in files)
    for path in files:
        path.write_bytes(b"\xff\xfe broken")
    assert caches.generated_text("gen", "key b", make("B")) == "B"
    assert made[-1] == "B"


def test_sources_digest__changes_with_any_source_of_the_package(tmp_path: Path) -> None:
    """The digest of a copy of the package changes when one of its files changes."""
    import shutil

    copy = tmp_path / "mcchain"
    shutil.copytree(REPO / "mcchain", copy, ignore=shutil.ignore_patterns("__pycache__"))
    code = "from mcchain.compiled.caches import sources_digest; print(sources_digest())"

    def digest() -> str:
        env = {**os.environ, "PYTHONPATH": str(tmp_path)}
        return subprocess.run([sys.executable, "-c", code], env=env, cwd=tmp_path, check=True,
                              capture_output=True, text=True).stdout.strip()  # fmt: skip

    before = digest()
    assert before == caches.sources_digest()  # the same files: the same digest
    with (copy / "contact.py").open("a") as fh:
        fh.write("\n# edited\n")
    assert digest() != before


def test_evict_oldest__only_the_files_of_its_pattern(tmp_path: Path) -> None:
    """Above the size, the least recently used files of the pattern go, never ``keep``."""
    for i, name in enumerate(("a.txt", "b.txt", "c.txt", "d.bin")):
        (tmp_path / name).write_bytes(b"x" * 100)
        os.utime(tmp_path / name, (1000 + i, 1000 + i))
    removed = caches.evict_oldest(tmp_path, 150, keep=tmp_path / "a.txt", pattern="*.txt")
    assert [p.name for p in removed] == ["b.txt", "c.txt"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt", "d.bin"]
