"""``within = [low, high]`` beside a distribution: the distribution truncated there, against
scipy's truncated distributions (exact quantiles), and its refusals."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydantic import ValidationError
from scipy import stats

from mcchain.scene.sampling import ppf
from mcchain.scene.study import Distribution

U = np.linspace(0.001, 0.999, 41)


def test_within__normal_lognormal_truncnormal_uniform_choice_against_scipy() -> None:
    normal = Distribution.model_validate({"normal": [1.0, 2.0], "within": [0.5, 4.0]})
    expected = stats.truncnorm.ppf(U, (0.5 - 1.0) / 2.0, (4.0 - 1.0) / 2.0, loc=1.0, scale=2.0)
    np.testing.assert_allclose(ppf(normal, U), expected, rtol=1e-12)
    assert normal.bounds() == (0.5, 4.0)

    lognormal = Distribution.model_validate({"lognormal": [0.0, 0.5], "within": [0.8, 2.0]})
    lo, hi = stats.norm.cdf(np.log([0.8, 2.0]), scale=0.5)
    expected = np.exp(0.5 * stats.norm.ppf(lo + U * (hi - lo)))
    np.testing.assert_allclose(ppf(lognormal, U), expected, rtol=1e-9)

    trunc = Distribution.model_validate(
        {"truncnormal": [0.0, 1.0, -1.0, 1.0], "within": [0.5, 3.0]}
    )
    assert trunc.bounds() == (0.5, 1.0)
    expected = stats.truncnorm.ppf(U, 0.5, 1.0)  # truncnormal cut again: truncated to [0.5, 1]
    np.testing.assert_allclose(ppf(trunc, U), expected, rtol=1e-9)

    uniform = Distribution.model_validate({"uniform": [0.0, 1.0], "within": [0.25, 0.5]})
    np.testing.assert_allclose(ppf(uniform, U), 0.25 + 0.25 * U, rtol=1e-14)

    choice = Distribution.model_validate({"choice": [1.0, 2.0, 3.0, 4.0], "within": [2.0, 3.5]})
    assert choice.bounds() == (2.0, 3.0)
    assert set(ppf(choice, U).tolist()) == {2.0, 3.0}


@pytest.mark.parametrize(
    ("table", "fragment"),
    [
        ({"uniform": [0.0, 1.0], "within": [2.0, 3.0]}, "does not overlap the uniform range"),
        ({"choice": [1.0, 2.0], "within": [3.0, 4.0]}, "no value of choice lies in"),
        ({"normal": [0.0, 1.0], "within": [1.0, 1.0]}, "low must be below high"),
        ({"within": [0.0, 1.0]}, "exactly one of"),
    ],
)
def test_within__refused_in_one_line(table: dict, fragment: str) -> None:
    with pytest.raises(ValidationError, match=fragment):
        Distribution.model_validate(table)


def test_within__values_stay_inside_at_the_ends() -> None:
    dist = Distribution.model_validate({"normal": [0.0, 1.0], "within": [3.0, 3.5]})
    x = ppf(dist, np.array([2.0**-53, 0.5, 1 - 2.0**-53]))
    assert np.all((x >= 3.0) & (x <= 3.5)) and not np.any(np.isnan(x))
    assert math.isclose(x[1], float(stats.truncnorm.ppf(0.5, 3.0, 3.5)), rel_tol=1e-9)
