"""Generated modules on disk: written once under a content hash, imported like any file.

The file name is the hash of the generated text, so numba's ``cache=True`` works for a
generated module as for any other file, and two processes generating the same module write
the same file.
"""

from __future__ import annotations

import hashlib
import importlib.util
import os
import sys
import tempfile
from pathlib import Path
from types import ModuleType
from typing import Any

from mcchain.compiled.caches import mcchain_cache

_GENERATOR_FILES = (
    "topology.py",
    "lane_text.py",
    "sincos.py",
    "kinematics.py",
    "emitter.py",
    "sparse_ldl.py",
    "inline.py",
    "layout.py",
    "templates.py",
    "tracking.py",
    "schedule.py",
    "generate.py",
)


def generator_hash() -> str:
    """Hash of the generator sources (the modules of this package that shape the text)."""
    h = hashlib.sha256()
    here = Path(__file__).parent
    for name in _GENERATOR_FILES:
        h.update((here / name).read_bytes())
    return h.hexdigest()[:16]


def copied_functions(*kernels: Any) -> str:
    """The source of numba kernels (their ``py_func``), each decorated ``@njit(**JIT)``, to
    paste into a generated module that calls them.

    Copied, not imported: numba's cache of a generated module is keyed by the module's own
    file, so a change of a function it imported would not reach the cached machine code;
    with the source in the text, such a change makes a new module (its name is the text's
    hash), and the native compiler sees one module."""
    import inspect

    parts = []
    for kernel in kernels:
        source = inspect.getsource(kernel.py_func)
        parts.append("@njit(**JIT)\n" + source[source.index("def ") :])
    return "\n\n".join(parts)


def cache_dir() -> Path:
    """Folder of generated kernel modules: ``generated`` in mcchain's cache
    (:func:`mcchain.compiled.caches.mcchain_cache`)."""
    return mcchain_cache("generated")


def load_module(source: str, prefix: str = "mcchain_gen") -> ModuleType:
    """Write ``source`` to the cache (atomically, once) and import it.

    The file name is the hash of the text, so two processes generating the same module write
    the same file, and numba finds its cached machine code beside it.
    """
    digest = hashlib.sha256(source.encode()).hexdigest()[:20]
    name = f"{prefix}_{digest}"
    if name in sys.modules:
        return sys.modules[name]
    folder = cache_dir()
    path = folder / f"{name}.py"
    if not path.exists() or path.read_text() != source:
        fd, tmp = tempfile.mkstemp(dir=folder, suffix=".tmp")
        with os.fdopen(fd, "w") as fh:
            fh.write(source)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    from mcchain.kernels.config import register_intrinsics

    register_intrinsics()  # the text calls mcchain.kernels.config's fma, prefetch, take_next
    spec = importlib.util.spec_from_file_location(name, path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module
