"""The branch-free sine/cosine of generated kernels, as numba functions (tests and tools).

Built from :func:`mcchain.codegen.sincos.sincos_code` and
:func:`~mcchain.codegen.sincos.rotated_sincos_code`, the very lines generated kernels inline.
"""

from __future__ import annotations

import math

import numpy as np

from mcchain.codegen.sincos import rotated_sincos_code, sincos_code
from mcchain.kernels.config import JIT, LANE_JIT, njit


def _sincos_function() -> str:
    body = "\n".join("    " + line for line in sincos_code("x", "s", "c", ""))
    return f"def sincos(x):\n{body}\n    return s, c\n"


def _rotated_function(name: str, short: bool) -> str:
    lines = rotated_sincos_code("s0", "c0", "delta", "s", "c", "", short=short)
    body = "\n".join("    " + line for line in lines)
    return f"def {name}(s0, c0, delta):\n{body}\n    return s, c\n"


_namespace: dict[str, object] = {"math": math, "np": np}
exec(_sincos_function(), _namespace)
exec(_rotated_function("rotated_sincos", short=False), _namespace)
exec(_rotated_function("short_rotated_sincos", short=True), _namespace)
# exec'd code has no file for numba's cache: compiled uncached (it serves tests and tools).
sincos = njit(**dict(JIT, cache=False))(_namespace["sincos"])
sincos.__doc__ = "(sin x, cos x) by the branch-free polynomial that generated kernels inline."
# With the lanes' options (fused multiply-adds allowed), as the lanes compile it.
rotated_sincos = njit(**dict(LANE_JIT, cache=False))(_namespace["rotated_sincos"])
rotated_sincos.__doc__ = (
    "(sin(θ₀ + δ), cos(θ₀ + δ)) from (sin θ₀, cos θ₀) and δ, as the rk4 lanes turn a body's "
    "step-start sine-cosine to a later stage (|δ| ≤ π/4 only)."
)
short_rotated_sincos = njit(**dict(LANE_JIT, cache=False))(_namespace["short_rotated_sincos"])
short_rotated_sincos.__doc__ = (
    "(sin(θ₀ + δ), cos(θ₀ + δ)) as rotated_sincos, by the short polynomials the rk4 lanes turn "
    "with where |δ| ≤ SHORT_ROTATION_BOUND."
)
