"""codegen.inline: the lane text of a kernel function computes what the function computes,
bit for bit (the lanes and the loop kernels share one definition of the contact law)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mcchain.codegen.inline import inline
from mcchain.contact import LAW_CODES
from mcchain.kernels import contact as kc


def _run(function, arguments: dict[str, float], suffix: str = "7") -> list[float]:
    """Evaluate the inlined text of ``function`` with the named arguments bound."""
    names = list(arguments)
    statements, results = inline(function.__module__, function.__name__, names, suffix)
    scope: dict[str, float] = dict(arguments)
    for line in statements:
        exec(line, {"math": math}, scope)
    return [eval(r, {"math": math}, scope) for r in results]


def _same(a: float, b: float) -> bool:
    return (a == b and math.copysign(1.0, a) == math.copysign(1.0, b)) or (a != a and b != b)


@pytest.mark.parametrize("law", sorted(LAW_CODES.values()))
def test_inline__contact_law_text_equals_the_kernel_bit_for_bit(law):
    rng = np.random.default_rng(law)
    for _ in range(300):
        args = {
            "pen": float(rng.choice([-1.0, 1.0]) * 10.0 ** rng.uniform(-9, -4)),
            "pdot": float(rng.normal() * 10.0 ** rng.uniform(-3, 0)),
            "ins": float(rng.integers(0, 2)),
            "vi": float(rng.choice([-1.0, 0.0, 1.0]) * rng.uniform(0.0, 2.0)),
            "K": float(10.0 ** rng.uniform(8, 11)),
            "mx": float(rng.choice([1.0, 1.5, 2.0])),
            "lw": float(law),
            "er": float(rng.uniform(0.05, 1.0)),
        }
        got = _run(kc.contact_law, args)
        want = kc.contact_law(*args.values())
        assert all(_same(g, w) for g, w in zip(got, want, strict=True)), (args, got, want)


def test_inline__friction_and_slip_text_equal_the_kernels_bit_for_bit():
    rng = np.random.default_rng(3)
    for _ in range(300):
        slip_args = {f"a{i}": float(rng.normal()) for i in range(8)}
        (slip,) = _run(kc.contact_slip, slip_args)
        assert _same(slip, kc.contact_slip(*slip_args.values()))
        args = {
            "fn": float(rng.uniform(0, 1e4)),
            "vt": float(rng.normal() * 10.0 ** rng.uniform(-5, 0)),
            "mu": float(rng.uniform(0, 0.5)),
        }
        (ft,) = _run(kc.friction_force, args)
        assert _same(ft, kc.friction_force(*args.values()))


def test_inline__renames_locals_with_the_suffix_and_writes_constants_as_floats():
    statements, results = inline(kc.__name__, "contact_law", [f"x{i}" for i in range(8)], "_3")
    assert statements[0] == "rate_3 = x2 * x3 + (1.0 - x2) * x1"
    assert f"x6 == {float(kc.FLORES)!r}" in statements[1]  # the law code as a float literal
    assert results == ["fn_3", "delta_slope_3", "rate_slope_3"]


def test_inline__refuses_code_outside_the_straight_line_subset():
    with pytest.raises(TypeError, match=r"unpack only|not straight-line"):
        inline(kc.__name__, "contact_crossing", ["a", "b", "c", "d", "h"], "0")
    with pytest.raises(TypeError, match="no such function"):
        inline(kc.__name__, "no_such_law", [], "0")
