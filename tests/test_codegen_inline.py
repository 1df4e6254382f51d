"""codegen.inline: the lane text of a kernel function computes what the function computes,
bit for bit (the lanes and the loop kernels share one definition of the contact law, of each
joint's Φ, Φ̇ and γ, of the driver laws and of the applied forces)."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from mcchain.codegen.inline import inline
from mcchain.contact import LAW_CODES
from mcchain.kernels import contact as kc
from mcchain.kernels import forces as kf
from mcchain.kernels import joints as kj
from mcchain.kernels.config import fma


def _run(function, arguments: dict[str, float], suffix: str = "7") -> list[float]:
    """Evaluate the inlined text of ``function`` with the named arguments bound."""
    names = list(arguments)
    statements, results = inline(function.__module__, function.__name__, names, suffix)
    scope: dict[str, float] = dict(arguments)
    for line in statements:
        exec(line, {"math": math, "fma": fma}, scope)
    return [eval(r, {"math": math, "fma": fma}, scope) for r in results]


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


NESTED = """
def outer(a, b):
    top = a + b
    low = inner(a, b)
    mid = top * 2.0
    return top - low + mid


def inner(a, b):
    top = a * b
    top = top + 1.0
    return top - a
"""


def test_inline__a_callees_local_named_like_its_callers_gets_its_own_name(tmp_path, monkeypatch):
    """Caller and callee share the suffix: the callee's ``top`` (reassigned in its own
    body, which keeps its name) is written as ``top_0_2``, and the caller's ``top`` keeps
    its value (the callee overwrote it: the text gave 35 where the function gives 11)."""
    (tmp_path / "nested_kernel.py").write_text(NESTED, encoding="utf-8")
    monkeypatch.syspath_prepend(str(tmp_path))
    statements, (result,) = inline("nested_kernel", "outer", ["x", "y"], "_0")
    assert statements == [
        "top_0 = x + y",
        "top_0_2 = x * y",
        "top_0_2 = top_0_2 + 1.0",
        "low_0 = top_0_2 - x",
        "mid_0 = top_0 * 2.0",
    ]
    namespace: dict[str, float] = {"x": 3.0, "y": 5.0}
    exec("\n".join(statements), namespace)
    namespace_outer: dict[str, object] = {}
    exec(NESTED, namespace_outer)
    assert eval(result, namespace) == namespace_outer["outer"](3.0, 5.0) == 11.0


def test_inline__refuses_code_outside_the_straight_line_subset():
    with pytest.raises(TypeError, match=r"unpack only|not straight-line"):
        inline(kc.__name__, "contact_crossing", ["a", "b", "c", "d", "h"], "0")
    with pytest.raises(TypeError, match="no such function"):
        inline(kc.__name__, "no_such_law", [], "0")


def _normal(rng: np.random.Generator) -> float:
    return float(rng.normal() * 10.0 ** rng.uniform(-3, 2))


# Each straight-line law of the joints and forces kernels, with a draw of its arguments.
JOINT_AND_FORCE_LAWS = {
    (kj, "rotate"): lambda rng: [_normal(rng) for _ in range(4)],
    (kj, "point_velocity"): lambda rng: [_normal(rng) for _ in range(5)],
    (kj, "centripetal"): lambda rng: [_normal(rng) for _ in range(6)],
    (kj, "separation"): lambda rng: [_normal(rng) for _ in range(8)],
    (kj, "separation_rate"): lambda rng: [_normal(rng) for _ in range(10)],
    (kj, "point_row"): lambda rng: [
        float(rng.choice([-1.0, 1.0])),
        *(_normal(rng) for _ in range(4)),
    ],
    (kj, "inverse_distance"): lambda rng: [  # |d| = 0 only where guarded (else 1/0)
        *((0.0, 1.0) if rng.random() < 0.3 else (abs(_normal(rng)), float(rng.integers(0, 2)))),
    ],
    (kj, "clearance_rate"): lambda rng: [_normal(rng) for _ in range(4)],
    (kj, "clearance_gamma"): lambda rng: [_normal(rng) for _ in range(8)],
    (kj, "distance_squared"): lambda rng: [_normal(rng) for _ in range(2)],
    (kj, "clearance_gamma_scaled"): lambda rng: [_normal(rng) for _ in range(7)],
    (kj, "axis_normal"): lambda rng: [_normal(rng) for _ in range(4)],
    (kj, "axis_turn"): lambda rng: [_normal(rng) for _ in range(6)],
    (kj, "prismatic_residual"): lambda rng: [_normal(rng) for _ in range(7)],
    (kj, "prismatic_rate"): lambda rng: [_normal(rng) for _ in range(8)],
    (kj, "prismatic_gamma"): lambda rng: [_normal(rng) for _ in range(9)],
    (kj, "harmonic_swing"): lambda rng: [_normal(rng) for _ in range(5)],
    (kj, "driver_residual"): lambda rng: [_normal(rng) for _ in range(5)],
    (kj, "driver_speed"): lambda rng: [_normal(rng) for _ in range(2)],
    (kf, "moment"): lambda rng: [_normal(rng) for _ in range(4)],
    (kf, "load_wrench"): lambda rng: [_normal(rng) for _ in range(6)],
    (kf, "spring_force"): lambda rng: [
        *[_normal(rng) for _ in range(5)],
        float(rng.choice([0.0, abs(_normal(rng))])),  # rest length 0: isotropic
        abs(_normal(rng)),
    ],
    (kf, "spring_energy"): lambda rng: [
        *[_normal(rng) for _ in range(3)],
        float(rng.choice([0.0, abs(_normal(rng))])),
    ],
    (kf, "load_potential"): lambda rng: [_normal(rng) for _ in range(6)],
    (kf, "gravity_potential"): lambda rng: [_normal(rng) for _ in range(5)],
    (kf, "body_kinetic_energy"): lambda rng: [_normal(rng) for _ in range(5)],
    (kc, "quasi_static_slack"): lambda rng: [_normal(rng) for _ in range(3)],
    (kc, "contact_mode"): lambda rng: [
        float(rng.integers(0, 2)),
        float(rng.choice([_normal(rng), 0.0, -0.0])),
        float(rng.choice([-2.0, -1.0, 0.0, abs(_normal(rng))])),  # seated at switch, seated
    ],
    (kc, "reseat_slack"): lambda rng: [
        float(rng.choice([kc.AUTO, 1])),  # model auto or contact
        *(float(rng.choice([_normal(rng), _normal(rng), math.nan])) for _ in range(5)),
        float(rng.choice([1.0, 1.5])),  # the law's exponent
        float(rng.integers(0, 2)),  # paid: a scene without drivers
    ],
}


@pytest.mark.parametrize(
    ("module", "name"), list(JOINT_AND_FORCE_LAWS), ids=[n for _, n in JOINT_AND_FORCE_LAWS]
)
def test_inline__joint_driver_and_force_laws_equal_the_kernels_bit_for_bit(module, name):
    """The lanes' text of each law, evaluated in Python, against the compiled kernel: the
    same IEEE operations in the same order give the same bits."""
    kernel = getattr(module, name)
    draw = JOINT_AND_FORCE_LAWS[module, name]
    rng = np.random.default_rng(sum(map(ord, name)))
    for _ in range(200):
        values = draw(rng)
        args = {f"x{i}": v for i, v in enumerate(values)}
        got = _run(kernel, args, suffix="_t")
        want = kernel(*values)
        want = want if isinstance(want, tuple) else (want,)
        assert all(_same(g, w) for g, w in zip(got, want, strict=True)), (name, values, got)


def _equal(a: float, b: float) -> bool:
    return a == b or (a != a and b != b)


@pytest.mark.parametrize(
    ("name", "literal"),
    [
        ("centripetal", {4: 0.0}),  # bearing on the ground: θ̇_a = 0
        ("centripetal", {5: 0.0}),  # journal on the ground
        ("prismatic_gamma", {8: 0.0}),
        ("prismatic_rate", {6: 0.0, 7: 0.0}),
        ("prismatic_residual", {4: 0.0}),
        ("axis_normal", {0: 1.0, 1: 0.0}),  # the ground's (cos, sin)
        ("driver_residual", {4: 0.0}),  # constant speed: no swing
        ("driver_speed", {1: 0.0}),
        ("inverse_distance", {1: 1.0}),
        ("separation", {0: 0.0, 1: 0.0}),  # bearing on the ground: r_a = 0
        ("separation_rate", {0: 0.0, 1: 0.0, 2: 0.0}),  # … at rest
        ("separation_rate", {5: 0.0, 6: 0.0, 7: 0.0}),  # journal on the ground
        ("point_row", {0: -1.0, 1: 1.0, 2: 0.0}),  # an ideal joint's x row on body a
        ("point_row", {0: 1.0, 1: 0.0, 2: 1.0}),  # … its y row on body b
    ],
)
def test_inline__literal_ground_terms_fold_to_the_kernels_values(name, literal):
    """With a literal 0.0 / 1.0 argument (a ground body's) the folded text gives the
    kernel's values for finite operands (equal as numbers: a zero's sign may differ)."""
    kernel = getattr(kj, name)
    draw = JOINT_AND_FORCE_LAWS[kj, name]
    rng = np.random.default_rng(5)
    for _ in range(200):
        values = draw(rng)
        for i, value in literal.items():
            values[i] = value
        names = [repr(v) if i in literal else f"x{i}" for i, v in enumerate(values)]
        statements, results = inline(kj.__name__, name, names, "_t")
        scope = {f"x{i}": v for i, v in enumerate(values)}
        for line in statements:
            exec(line, {"math": math}, scope)
        got = [eval(r, {"math": math}, scope) for r in results]
        want = kernel(*values)
        want = want if isinstance(want, tuple) else (want,)
        assert all(_equal(g, w) for g, w in zip(got, want, strict=True)), (name, values, got)
    folded = inline(kj.__name__, name, names, "_t")[1]
    assert not any(
        re.search(r"\* 0\.0\b|\b0\.0 \*|- 0\.0\b|\+ 0\.0\b|\b1\.0 \*", r) for r in folded
    )


def test_inline__distance_is_hypot_in_the_kernels_and_a_root_of_squares_in_the_lanes():
    """The one deliberate difference between the two targets: libm's hypot (robust) against
    √(dx² + dy²) (vectorises), at most an ulp apart on lengths of 1e-6 … 1e2 m."""
    (text,) = inline(kj.__name__, "distance", ["x0", "x1"], "")[1]
    assert text == "math.sqrt(x0 * x0 + x1 * x1)"
    rng = np.random.default_rng(11)
    for _ in range(2000):
        dx, dy = (float(rng.normal() * 10.0 ** rng.uniform(-6, 2)) for _ in range(2))
        (got,) = _run(kj.distance, {"x0": dx, "x1": dy})
        want = kj.distance(dx, dy)
        assert abs(got - want) <= math.ulp(want), (dx, dy, got, want)
