"""contact_power: δ^m of the contact law, δ^1.5 correctly rounded without libm's pow
(hertz_power, through fma), and the rk45 lanes' copy of the stage for lane groups whose
exponents are all 1.5 (the same values as the general stage)."""

from __future__ import annotations

import math
import re
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

from mcchain.kernels.config import fma
from mcchain.kernels.contact import HERTZ_EXACT_MAX, contact_power, hertz_power
from mcchain.solvers.simulate import simulate
from mcchain.solvers.statics import assemble
from mcchain.testing.scenes import model_of

CONFIGS = Path(__file__).resolve().parent.parent / "configs"


def _correctly_rounded(x: float, y: float) -> bool:
    """Whether ``y`` is the double nearest to x^1.5 (x > 0 finite, y > 0 finite): x³ lies
    between the squares of the midpoints to y's neighbours (exact rationals)."""
    cube = Fraction(x) ** 3
    low = (Fraction(y) + Fraction(math.nextafter(y, 0.0))) / 2
    high = (Fraction(y) + Fraction(math.nextafter(y, math.inf))) / 2
    return low * low <= cube <= high * high


def test_hertz_power__correctly_rounded_where_libm_pow_is_not_always():
    rng = np.random.default_rng(11)
    # penetrations (1e-12 .. 1e-2 m) and the whole range the correction holds over
    xs = np.concatenate([10.0 ** rng.uniform(-12, -2, 3000), 10.0 ** rng.uniform(-200, 200, 3000)])
    off = 0
    for x in map(float, xs):
        y = hertz_power(x)
        assert _correctly_rounded(x, y), x
        p = x**1.5  # libm's pow, as the kernels called it before
        off += p != y
        assert abs(p - y) <= math.ulp(y), x  # pow is within an ulp
    # pow is an ulp off in ~0.08 % of values (2·10⁷ checked in C): here a handful at most
    assert off <= 20


def test_hertz_power__edges():
    assert hertz_power(0.0) == 0.0
    assert math.isnan(hertz_power(math.nan))
    assert hertz_power(math.inf) == math.inf
    assert hertz_power(4.0) == 8.0 and hertz_power(0.25) == 0.125  # exact powers stay exact
    assert hertz_power(1e300) == math.inf  # overflow: inf, as pow
    big = 1.5 * HERTZ_EXACT_MAX  # above the bound: x √x, within an ulp of pow
    assert abs(hertz_power(big) - big**1.5) <= math.ulp(big**1.5)
    for tiny in (1e-250, 1e-210, 5e-324):  # subnormal results: within an ulp of pow
        assert abs(hertz_power(tiny) - tiny**1.5) <= 5e-324


def test_contact_power__pow_for_other_exponents_and_hertz_power_for_1_5():
    rng = np.random.default_rng(5)
    for delta in map(float, 10.0 ** rng.uniform(-10, -3, 200)):
        for m in (1.0, 1.2, 2.0, 2.5):
            assert contact_power(delta, m) == delta**m
        assert contact_power(delta, 1.5) == hertz_power(delta)
    assert contact_power(0.0, 1.5) == 0.0 and contact_power(0.0, 1.0) == 0.0


def test_fma__interpreted_equals_the_compiled_one():
    """config.fma as plain Python (exact rationals, rounded once) gives the compiled
    llvm.fma's value, also where a·b cancels c (the error term of a product)."""
    from numba import njit

    compiled = njit(lambda a, b, c: fma(a, b, c))
    rng = np.random.default_rng(2)
    for _ in range(2000):
        a, b = (float(v) for v in rng.normal(size=2) * 10.0 ** rng.uniform(-20, 20, 2))
        for c in (float(rng.normal()), -(a * b), -(math.sqrt(abs(a)) ** 2)):
            assert fma(a, b, c) == compiled(a, b, c), (a, b, c)
    assert math.isnan(fma(math.inf, 0.0, 1.0)) and math.isnan(compiled(math.inf, 0.0, 1.0))
    assert fma(1e308, 10.0, -1e308) == compiled(1e308, 10.0, -1e308) == math.inf


LANES = 4


def _mixed_exponents(seed: int):
    """The requirement slider-crank (6 ms, no outputs) with the pin's stiffness given and its
    exponent drawn from {1.5, 2.0}: groups of LANES lanes that mix the two."""
    text = (CONFIGS / "slider-crank-requirement.toml").read_text()
    text = text.split("\n[sample]")[0].split("\n[[output]]")[0]
    text = re.sub(r"radius = 0\.01.*\n.*\n.*\n", "radius = 0.01\nstiffness = 1e10\n", text)
    text = text.replace("t_end = 0.024", "t_end = 0.006")
    text += (
        f'\n[sample]\ncount = {4 * LANES}\nseed = {seed}\ndesign = "random"\n[sample.vary]\n'
        '"joint.B.contact.exponent" = { choice = [1.5, 2.0] }\n'
        '"joint.B.clearance" = { uniform = [1e-4, 5e-4] }\n'
    )
    model = model_of(text)
    column = list(model.param_paths).index("joint.B.contact.exponent")
    return model, np.asarray(model.parameters)[:, column]


@pytest.mark.parametrize("seed", [2])
def test_rk45_lanes__hertz_copy_and_general_stage_give_the_same_bits(seed):
    """A lane group whose exponents are all 1.5 runs the stage's copy without pow; a group
    that mixes 1.5 and 2.0 runs the general stage (a select between contact_power's two
    branches). A sample of exponent 1.5 gets the same values bit for bit in a mixed group of
    LANES and alone in a group of one (the copy), and every sample's values do not depend on
    the lanes beside it."""
    model, exponent = _mixed_exponents(seed)
    groups = exponent.reshape(-1, LANES)
    # the premise: every group of LANES mixes the two exponents
    assert ((groups == 1.5).any(axis=1) & (groups == 2.0).any(axis=1)).all(), groups
    start = assemble(model)
    sim = dict(t_end=6e-3, dt=1e-7, output_dt=1e-4, method="rk45", rtol=1e-7, atol=1e-10,
               kernels="lanes")  # fmt: skip
    grouped = simulate(model, sim, start.q, start.v, np.float64, lanes=LANES)
    alone = simulate(model, sim, start.q, start.v, np.float64, lanes=1)
    assert (grouped["status"] == 0).all() and np.isfinite(grouped["q"]).all()
    # the law acted (δ > 0: δ^m computed on a penetration) in samples of both exponents
    joint = list(model.joint_names).index("B")
    pressed = grouped["max_penetration"][:, joint] > 0
    assert pressed[exponent == 1.5].sum() >= 3 and pressed[exponent == 2.0].sum() >= 3
    for name, values in grouped.items():
        if isinstance(values, np.ndarray):
            assert np.array_equal(values, alone[name], equal_nan=True), name
