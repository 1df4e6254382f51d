"""Numba's cached kernels are dropped when any kernel source changed, not only their own
file: a kernel holds the machine code of the callees it inlined from other files (after
``write_outputs`` learnt to store nothing for 0-length histories, a stale
``generalized_alpha_run`` still stored past the end of them and crashed the process)."""

from __future__ import annotations

from pathlib import Path

import pytest

from mcchain.kernels import config


def test_drop_stale_kernels__removes_cached_kernels_of_other_sources_once(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    folders = [tmp_path / "kernels", tmp_path / "top"]
    for folder in folders:
        folder.mkdir()
        for name in ("implicit.run-73.py311.nbi", "implicit.run-73.py311.1.nbc", "a.pyc"):
            (folder / name).write_bytes(b"x")
    (folders[1] / config.KERNEL_STAMP).write_text("an older digest\n", encoding="ascii")
    monkeypatch.setattr(config, "kernel_cache_folders", lambda: [*folders, tmp_path / "none"])
    assert config.drop_stale_kernels() == 4
    for folder in folders:
        assert sorted(p.name for p in folder.iterdir()) == ["a.pyc", config.KERNEL_STAMP]
        stamp = (folder / config.KERNEL_STAMP).read_text(encoding="ascii").strip()
        assert stamp == config.kernel_sources_digest()
    (folders[0] / "implicit.run-73.py311.nbi").write_bytes(b"x")  # compiled from these
    assert config.drop_stale_kernels() == 0
    assert (folders[0] / "implicit.run-73.py311.nbi").exists()
    assert not (tmp_path / "none").exists()


def test_kernel_sources_digest__changes_with_a_callee_file(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    package = tmp_path / "mcchain"
    (package / "kernels").mkdir(parents=True)
    (package / "kernels" / "config.py").write_text("", encoding="utf-8")
    (package / "codes.py").write_text("A = 1\n", encoding="utf-8")
    monkeypatch.setattr(config, "__file__", str(package / "kernels" / "config.py"))
    before = config.kernel_sources_digest()
    (package / "codes.py").write_text("A = 2\n", encoding="utf-8")
    assert config.kernel_sources_digest() != before


def test_kernel_cache_folders__hold_where_numba_itself_caches_a_kernel() -> None:
    """The folder numba's own cache locator chose for a kernel of mcchain/kernels (beside
    the sources, in NUMBA_CACHE_DIR or user-wide, as this process has it) is one of those
    whose stale files are dropped."""
    from mcchain.kernels import linalg

    folders = config.kernel_cache_folders()
    assert len(folders) == len(config.KERNEL_SOURCE_DIRS)
    assert Path(linalg.lu_factor._cache._cache_path) in folders
