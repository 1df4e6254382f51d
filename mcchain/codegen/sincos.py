"""The branch-free sine and cosine that generated lane code inlines, as text.

fdlibm kernels on [-π/4, π/4] after a three-part Cody–Waite reduction. Branch-free (the
quadrant's swap and signs exact 0/1 and ±1 factors), so the lane loop vectorises, and free of
function calls: rounding to an integer is
(y + 1.5·2⁵²) − 1.5·2⁵², exact for |y| < 2⁵¹ (so for |x| < 3.5e15 rad; the reduction itself
stays ≤ 1 ulp-ish for |x| < 1e6 rad). Calls such as np.floor cost numba's type inference more
than anything else in generated code.

The quadrant j = k mod 4 takes one more rounding: m = k − 4·round(k/4) ∈ {−2, …, 2}, j = m + 4
where m < 0 (a select), every step in vector registers. As an integer (``int(k) & 3``) it
needed four scalar conversions and their shuffles a sine-cosine on AVX2, which has no vector
conversion of doubles to 64-bit integers, on the lane group's critical path (the verdict
kernel 0.940 with the rounding, the rk4 lanes unchanged: benchmarks/results/verdict/
combine.md); an older rounding form (a floor by offsets, two roundings) cost 12 flops more.
Its swap and signs stay the factors
sw·p_c + (1 − sw)·p_s and 1 − 2h: as selects (9 flops fewer again) they gave the same sine
and cosine, but LLVM then fused the other product of a·sin θ + b·cos θ into its multiply-add
(selects of ±x are not multiplies), which moved the lanes' results by an ulp.

:func:`rotated_sincos_code` is the sine-cosine of θ₀ + δ from that of θ₀ and the same two
polynomials at δ itself (no reduction, no quadrant: a shorter chain), valid only where
|δ| ≤ :data:`ROTATION_BOUND`, the polynomials' own interval; with ``short=True`` by Taylor
polynomials of degree 7 (sine) and 6 (cos δ − 1), valid only where |δ| ≤
:data:`SHORT_ROTATION_BOUND`, on which interval their error is no larger than fdlibm's on
theirs.
"""

from __future__ import annotations

import math

TWO_PI = 2.0 * math.pi
_ROUND = "6755399441055744.0"  # 1.5 · 2⁵²: adding and subtracting it rounds to an integer

# fdlibm's __kernel_sin and __kernel_cos (FreeBSD msun k_sin.c, k_cos.c) of {r} (z = r²): sin r
# as {ps}; cos r = 1 − z/2 + z·_COS_TAIL, whose 1 − z/2 the kernel rounds in two parts.
# Within about an ulp for |r| ≤ π/4.
_SIN = (
    "{ps} = {r} + ({z} * {r}) * (-0.16666666666666632 + {z} * (0.008333333333322489"
    " + {z} * (-0.00019841269829857949 + {z} * (2.755731370707007e-06"
    " + {z} * (-2.5050760253406863e-08 + {z} * 1.5896909952115501e-10)))))"
)
_COS_TAIL = (
    "{z} * (0.0416666666666666 + {z} * (-0.0013888888888874109 + {z} * (2.480158728947673e-05"
    " + {z} * (-2.7557314351390663e-07 + {z} * (2.087572321298175e-09"
    " + {z} * -1.1359647557788195e-11)))))"
)
_KERNELS = "\n".join(
    [
        "{z} = {r} * {r}",
        _SIN,
        "{hz} = 0.5 * {z}",
        "{w} = 1.0 - {hz}",
        "{pc} = {w} + (((1.0 - {w}) - {hz}) + {z} * (" + _COS_TAIL + "))",
    ]
)

_SINCOS_TEMPLATE = "\n".join(
    [
        f"{{k}} = ({{x}} * 0.6366197723675814 + {_ROUND}) - {_ROUND}",
        "{r} = (({x} - {k} * 1.5707963267341256) - {k} * 6.077100506303966e-11)"
        " - {k} * 2.0222662487111665e-21",
        _KERNELS,
        # Quadrant j = k mod 4 ∈ {0, 1, 2, 3} (k a whole number, m = k − 4 round(k/4) exact,
        # negative m wrapped); h: j ≥ 2; sw: odd j (sine and cosine swap); the sine's sign
        # is 1 − 2h, the cosine's (1 − 2h)(1 − 2 sw).
        f"{{m}} = {{k}} - 4.0 * (({{k}} * 0.25 + {_ROUND}) - {_ROUND})",
        "{j} = {m} + 4.0 if {m} < 0.0 else {m}",
        "{h} = 1.0 if {j} >= 2.0 else 0.0",
        "{sw} = {j} - 2.0 * {h}",
        "{ss} = 1.0 - 2.0 * {h}",
        "{sa} = {sw} * {pc} + (1.0 - {sw}) * {ps}",
        "{ca} = {sw} * {ps} + (1.0 - {sw}) * {pc}",
        "{sin} = {ss} * {sa}",
        "{cos} = ({ss} * (1.0 - 2.0 * {sw})) * {ca}",
    ]
)


def sincos_code(x: str, sin: str, cos: str, tag: str) -> list[str]:
    """Lines computing ``sin``/``cos`` of the expression ``x`` (temporaries suffixed ``tag``)."""
    temps = ("k", "r", "z", "ps", "hz", "w", "pc", "j", "h", "sw", "ss", "sa", "ca", "m")
    names = {n: f"_{n}{tag}" for n in temps}
    return _SINCOS_TEMPLATE.format(x=x, sin=sin, cos=cos, **names).splitlines()


ROTATION_BOUND = math.pi / 4
"""Largest |δ| for :func:`rotated_sincos_code`: the interval of fdlibm's polynomials (measured:
1.1e-16 on it, 4e-14 at 1 rad, 2.5e-10 at π/2)."""

SHORT_ROTATION_BOUND = 0.02
"""Largest |δ| for :func:`rotated_sincos_code` with ``short=True``. Its Taylor polynomials'
error on [−0.02, 0.02] is at most 1.4e-21 (sine) and 6.4e-19 (cos δ − 1), fdlibm's on [−π/4,
π/4] reaches 2.7e-18 and 9.8e-19 (tests/test_codegen_rotation.py proves it). A stage's
increment δ = a h θ̇ is within it up to θ̇ = 0.02 / h (200 rad/s at h = 0.1 ms)."""

# Taylor to δ⁷ and to δ⁶ (the coefficients 1/3!, 1/5!, 1/7! and 1/4!, 1/6! rounded to doubles).
_SHORT_SIN = (
    "{ps} = {r} + ({z} * {r}) * (-0.16666666666666666 + {z} * (0.008333333333333333"
    " + {z} * -0.0001984126984126984))"
)
_SHORT_COS_TAIL = "{z} * (0.041666666666666664 + {z} * -0.001388888888888889)"

# sin δ and cos δ − 1 (cos δ − 1 without the 1, so that its small value keeps its own relative
# precision); then sin(θ₀ + δ) = s₀ + (s₀ (cos δ − 1) + c₀ sin δ), cos(θ₀ + δ) = c₀ + (c₀
# (cos δ − 1) − s₀ sin δ): s₀ and c₀ plus a correction that is small for small δ, so their own
# rounding and one more are most of the error (measured within 2.2e-16 of the true value for
# |δ| ≤ 0.5, 3.3e-16 up to π/4; the full evaluation: 1.1e-16).
_TURN = (
    "{sin} = {s0} + ({s0} * {cm} + {c0} * {ps})",
    "{cos} = {c0} + ({c0} * {cm} - {s0} * {ps})",
)
_ROTATED_TEMPLATE = "\n".join(
    ["{z} = {r} * {r}", _SIN, "{cm} = {z} * (-0.5 + " + _COS_TAIL + ")", *_TURN]
)
_SHORT_ROTATED_TEMPLATE = "\n".join(
    ["{z} = {r} * {r}", _SHORT_SIN, "{cm} = {z} * (-0.5 + " + _SHORT_COS_TAIL + ")", *_TURN]
)


def rotated_sincos_code(
    s0: str, c0: str, delta: str, sin: str, cos: str, tag: str, short: bool = False
) -> list[str]:
    """Lines computing ``sin``/``cos`` of θ₀ + δ from ``s0``/``c0`` (those of θ₀) and the
    expression ``delta`` (δ, rad), temporaries suffixed ``tag``. Only where
    |δ| ≤ :data:`ROTATION_BOUND`, or |δ| ≤ :data:`SHORT_ROTATION_BOUND` if ``short`` (the
    caller checks it, and takes the longer form or :func:`sincos_code` elsewhere). At δ = 0
    the result is s0, c0 (up to the sign of a zero)."""
    names = {n: f"_{n}{tag}" for n in ("z", "ps", "cm")}
    template = _SHORT_ROTATED_TEMPLATE if short else _ROTATED_TEMPLATE
    lines = template.format(s0=s0, c0=c0, r=f"_d{tag}", sin=sin, cos=cos, **names)
    return [f"_d{tag} = {delta}", *lines.splitlines()]
