"""codegen: pure Python — importing the generator never imports numba."""

from __future__ import annotations

import importlib
import sys

CODEGEN_MODULES = (
    "mcchain.codegen",
    "mcchain.codegen.adaptive_step",
    "mcchain.codegen.cache",
    "mcchain.codegen.contact_blocks",
    "mcchain.codegen.emitter",
    "mcchain.codegen.kinematics",
    "mcchain.codegen.lane_text",
    "mcchain.codegen.sincos",
    "mcchain.codegen.generate",
    "mcchain.codegen.layout",
    "mcchain.codegen.schedule",
    "mcchain.codegen.templates",
    "mcchain.codegen.tracking",
    "mcchain.codegen.topology",
)


def _fresh(name: str) -> bool:
    return name.split(".")[0] in {"mcchain", "numba"}


def test_codegen__imports_without_numba():
    """Every codegen module imports with numba made unimportable (in this process: the
    mcchain and numba modules already loaded are set aside, then put back)."""
    saved = dict(sys.modules)
    try:
        for name in [n for n in sys.modules if _fresh(n)]:
            del sys.modules[name]
        sys.modules["numba"] = None  # type: ignore[assignment]  # `import numba` now fails
        for name in CODEGEN_MODULES:
            importlib.import_module(name)
        assert not [n for n in sys.modules if n.startswith("numba.")]
    finally:
        sys.modules.clear()
        sys.modules.update(saved)
