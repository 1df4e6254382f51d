"""The branch-free sine/cosine of generated kernels, as a numba function (tests and tools).

Built from :func:`mcchain.codegen.sincos.sincos_code`, the very lines generated kernels
inline.
"""

from __future__ import annotations

import math

import numpy as np

from mcchain.codegen.sincos import sincos_code
from mcchain.kernels.config import JIT, njit


def _sincos_function() -> str:
    body = "\n".join("    " + line for line in sincos_code("x", "s", "c", ""))
    return f"def sincos(x):\n{body}\n    return s, c\n"


_namespace: dict[str, object] = {"math": math, "np": np}
exec(_sincos_function(), _namespace)
# exec'd code has no file for numba's cache: compiled uncached (it serves tests and tools).
sincos = njit(**dict(JIT, cache=False))(_namespace["sincos"])
sincos.__doc__ = "(sin x, cos x) by the branch-free polynomial that generated kernels inline."
