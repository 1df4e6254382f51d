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

from mcchain import caches
from mcchain.codegen.cache import cache_dir

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture
def blocked(tmp_path: Path) -> Path:
    """A folder path that cannot be made, for any user: its parent is a regular file."""
    (tmp_path / "a-file").write_text("")
    return tmp_path / "a-file" / "cache"


@pytest.fixture(autouse=True)
def fresh_warnings(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(caches, "_warned", set())


def test_writable__a_folder_under_a_file_is_not(blocked: Path, tmp_path: Path) -> None:
    assert not caches.writable(blocked)
    assert caches.writable(tmp_path / "new" / "folder")


def test_numba_cache__unwritable_dir_moves_to_temp_with_one_warning(
    blocked: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr(config, "CACHE_DIR", str(blocked))
    where = caches.ensure_numba_cache()
    caches.ensure_numba_cache()  # warned once only
    err = capsys.readouterr().err.splitlines()
    assert where == config.CACHE_DIR == str(caches.temporary_cache("numba"))
    assert len(err) == 1
    assert err[0].startswith(f"mcchain: warning: NUMBA_CACHE_DIR {blocked} cannot be written")


def test_numba_cache__writable_dir_is_kept_silently(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr(config, "CACHE_DIR", str(tmp_path / "numba"))
    assert caches.ensure_numba_cache() == str(tmp_path / "numba")
    assert capsys.readouterr().err == ""


def test_generated_cache__unwritable_dir_moves_to_temp_with_one_warning(
    blocked: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setenv("MCCHAIN_CACHE_DIR", str(blocked))
    assert cache_dir() == caches.temporary_cache("generated")
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
    monkeypatch.setattr(caches, "_fresh", {})
    return folder


def test_temporary_cache__made_private(own_tmp: Path, capsys: pytest.CaptureFixture[str]) -> None:
    folder = caches.temporary_cache("native")
    assert folder == own_tmp / f"mcchain-native-{os.getuid()}"
    assert folder.stat().st_mode & 0o777 == 0o700
    assert caches.temporary_cache("native") == folder and capsys.readouterr().err == ""


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
    folder = caches.temporary_cache("native")
    assert folder != planted and folder.parent == own_tmp
    assert folder.name.startswith(f"mcchain-native-{os.getuid()}-")
    assert folder.stat().st_mode & 0o777 == 0o700 and not any(folder.iterdir())
    assert caches.temporary_cache("native") == folder  # the same one for the process
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
