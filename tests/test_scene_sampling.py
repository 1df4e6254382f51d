"""Sampling designs and distributions: generator identity, moments, designs, determinism."""

from __future__ import annotations

import numpy as np
import pytest
from SALib.sample import sobol as salib_sobol
from scipy import stats

from mcchain.scene import Distribution, Sample, ppf, sample_parameters, unit_design
from mcchain.scene.sampling import philox4x32, philox_uniform

N_MOMENTS = 100_000
"""Samples for the moment checks."""
SE_TOL = 5.0
"""Allowed deviation of a sample mean, in standard errors (false alarm rate ~6e-7)."""
VAR_REL_TOL = 5.0 * np.sqrt(2.0 / N_MOMENTS)
"""Allowed relative error of a sample variance: 5 standard errors of s²/σ² for a normal."""


def _dist(**kw: list[float]) -> Distribution:
    return Distribution.model_validate(kw)


def _u(n: int = N_MOMENTS, seed: int = 11) -> np.ndarray:
    return philox_uniform(seed, 0, n, 1)[:, 0]


# -- Philox4x32-10 -------------------------------------------------------------------------
# Random123 tests/kat_vectors, the three "philox4x32 10" lines: counter, key, result.
KAT = [
    ((0, 0, 0, 0), (0, 0), (0x6627E8D5, 0xE169C58D, 0xBC57AC4C, 0x9B00DBD8)),
    (
        (0xFFFFFFFF,) * 4,
        (0xFFFFFFFF, 0xFFFFFFFF),
        (0x408F276D, 0x41C83B0E, 0xA20BC7C6, 0x6D5451FD),
    ),
    (
        (0x243F6A88, 0x85A308D3, 0x13198A2E, 0x03707344),
        (0xA4093822, 0x299F31D0),
        (0xD16CFE09, 0x94FDCCEB, 0x5001E420, 0x24126EA1),
    ),
]


@pytest.mark.parametrize(("counter", "key", "expected"), KAT)
def test_philox4x32__random123_known_answers(
    counter: tuple[int, ...], key: tuple[int, int], expected: tuple[int, ...]
) -> None:
    words = philox4x32(tuple(np.array([c], dtype=np.uint64) for c in counter), key)  # type: ignore[arg-type]
    assert tuple(int(w[0]) for w in words) == expected


def test_philox_uniform__open_interval_and_pure_function_of_seed_row_column() -> None:
    full = philox_uniform(7, 0, 1000, 5)
    assert full.shape == (1000, 5)
    assert np.all(full > 0.0) and np.all(full < 1.0)
    np.testing.assert_array_equal(philox_uniform(7, 250, 260, 5), full[250:260])
    np.testing.assert_array_equal(philox_uniform(7, 0, 1000, 3), full[:, :3])
    assert not np.array_equal(philox_uniform(8, 0, 1000, 5), full)


def test_philox_uniform__large_seed_and_index() -> None:
    u = philox_uniform(2**64 - 1, 2**40, 2**40 + 4, 2)
    assert u.shape == (4, 2) and np.all((u > 0) & (u < 1))
    with pytest.raises(ValueError, match="seed"):
        philox_uniform(2**64, 0, 1, 1)


# -- distributions -------------------------------------------------------------------------
def test_ppf__uniform_moments() -> None:
    lo, hi = 1e-4, 1e-3
    x = ppf(_dist(uniform=[lo, hi]), _u())
    assert x.min() >= lo and x.max() <= hi
    se = (hi - lo) / np.sqrt(12 * N_MOMENTS)
    assert abs(x.mean() - (lo + hi) / 2) < SE_TOL * se
    assert x.var() == pytest.approx((hi - lo) ** 2 / 12, rel=VAR_REL_TOL)


def test_ppf__normal_moments() -> None:
    x = ppf(_dist(normal=[2.0, 0.02]), _u())
    assert abs(x.mean() - 2.0) < SE_TOL * 0.02 / np.sqrt(N_MOMENTS)
    assert x.var() == pytest.approx(0.02**2, rel=VAR_REL_TOL)


def test_ppf__normal_is_the_inverse_cdf_to_a_few_ulp() -> None:
    """Against scipy's Φ⁻¹ (cephes ndtri) from 1e-300 to 1 - 1e-16, and exactly the
    standard library's NormalDist (the same algorithm, AS241)."""
    from statistics import NormalDist

    from scipy.special import ndtri

    u = np.concatenate(
        [10.0 ** -np.arange(1.0, 301.0), _u(2000), 1 - 10.0 ** -np.arange(1.0, 17.0)]
    )
    z = ppf(_dist(normal=[0.0, 1.0]), u)
    assert np.max(np.abs(z - ndtri(u)) / np.spacing(np.abs(ndtri(u)))) <= 8
    np.testing.assert_array_equal(z, [NormalDist().inv_cdf(p) for p in u])
    x = ppf(_dist(lognormal=[0.5, 0.3]), u)
    np.testing.assert_allclose(np.log(x), 0.5 + 0.3 * ndtri(u), rtol=1e-14, atol=1e-15)


def test_ppf__normal_zero_std_is_constant() -> None:
    np.testing.assert_array_equal(ppf(_dist(normal=[2.0, 0.0]), _u(100)), 2.0)


def test_ppf__lognormal_moments_of_log() -> None:
    x = ppf(_dist(lognormal=[0.5, 0.3]), _u())
    assert np.all(x > 0)
    assert abs(np.log(x).mean() - 0.5) < SE_TOL * 0.3 / np.sqrt(N_MOMENTS)
    assert np.log(x).var() == pytest.approx(0.09, rel=VAR_REL_TOL)


def test_ppf__truncnormal_within_bounds_and_moments() -> None:
    mean, std, lo, hi = 2.0, 0.5, 1.5, 3.5
    x = ppf(_dist(truncnormal=[mean, std, lo, hi]), _u())
    assert x.min() >= lo and x.max() <= hi
    ref = stats.truncnorm((lo - mean) / std, (hi - mean) / std, loc=mean, scale=std)
    assert abs(x.mean() - ref.mean()) < SE_TOL * ref.std() / np.sqrt(N_MOMENTS)
    assert x.var() == pytest.approx(ref.var(), rel=VAR_REL_TOL * 2)  # not normal: wider


def test_ppf__truncnormal_far_tail_stays_within_bounds() -> None:
    x = ppf(_dist(truncnormal=[0.0, 1.0, 0.0, 1e-3]), _u(10_000))
    assert x.min() >= 0.0 and x.max() <= 1e-3


def test_ppf__choice_frequencies() -> None:
    values = [0.1, 0.2, 0.7]
    x = ppf(_dist(choice=values), _u())
    assert set(np.unique(x)) == set(values)
    for v in values:
        freq = np.mean(x == v)
        assert abs(freq - 1 / 3) < SE_TOL * np.sqrt((1 / 3) * (2 / 3) / N_MOMENTS)


def test_ppf__choice_edges() -> None:
    d = _dist(choice=[1.0, 2.0])
    np.testing.assert_array_equal(
        ppf(d, np.array([1e-16, 0.5 - 1e-16, 0.5, 1 - 1e-16])), [1, 1, 2, 2]
    )


# -- designs -------------------------------------------------------------------------------
@pytest.mark.parametrize("design", ["random", "sobol", "saltelli"])
def test_unit_design__rows_do_not_depend_on_count(design: str) -> None:
    big = unit_design(design, 3, 1000, seed=5)
    small = unit_design(design, 3, 10, seed=5)
    np.testing.assert_array_equal(small, big[:10])
    np.testing.assert_array_equal(
        unit_design(design, 3, 1000, seed=5, start=300, stop=340), big[300:340]
    )


@pytest.mark.parametrize("design", ["random", "sobol", "lhs", "saltelli"])
def test_unit_design__reproducible_from_seed(design: str) -> None:
    a = unit_design(design, 2, 256, seed=42)
    np.testing.assert_array_equal(a, unit_design(design, 2, 256, seed=42))
    assert not np.array_equal(a, unit_design(design, 2, 256, seed=43))
    assert np.all((a > 0) & (a < 1))


def test_unit_design__sobol_is_stratified_and_cell_centred() -> None:
    n = 1024
    u = unit_design("sobol", 2, n, seed=3)
    for j in range(2):
        np.testing.assert_array_equal(np.sort(np.floor(u[:, j] * n)), np.arange(n))
    cells = (u - 2.0**-31) * 2.0**30
    np.testing.assert_array_equal(cells, np.round(cells))


def test_unit_design__lhs_one_point_per_stratum() -> None:
    n = 500
    u = unit_design("lhs", 3, n, seed=3)
    for j in range(3):
        np.testing.assert_array_equal(np.sort(np.floor(u[:, j] * n)), np.arange(n))


def test_unit_design__lhs_slices_match_full_draw() -> None:
    full = unit_design("lhs", 2, 100, seed=1)
    np.testing.assert_array_equal(
        unit_design("lhs", 2, 100, seed=1, start=20, stop=30), full[20:30]
    )


@pytest.mark.parametrize("d", [1, 2, 5])
def test_unit_design__saltelli_is_salibs_first_and_total_order_layout(d: int) -> None:
    ngroup, seed = 32, 11
    u = unit_design("saltelli", d, ngroup * (d + 2), seed=seed)
    # the structure: per base point A, AB_1 .. AB_d, B with AB_j = A but column j from B
    groups = u.reshape(ngroup, d + 2, d)
    a, b = groups[:, 0], groups[:, d + 1]
    assert np.all(a != b)
    for j in range(d):
        ab = a.copy()
        ab[:, j] = b[:, j]
        np.testing.assert_array_equal(groups[:, 1 + j], ab)
    # A and B are the halves of the "sobol" design's points in 2d columns
    np.testing.assert_array_equal(np.hstack([a, b]), unit_design("sobol", 2 * d, ngroup, seed))
    # and the whole is SALib's own sampler with the same scrambling, up to the cell centring
    problem = {"num_vars": d, "names": [f"x{j}" for j in range(d)], "bounds": [[0.0, 1.0]] * d}
    salib = salib_sobol.sample(
        problem, ngroup, calc_second_order=False, seed=np.random.default_rng(seed)
    )
    np.testing.assert_array_equal(u - 2.0**-31, salib)


def test_unit_design__saltelli_slices_and_counts() -> None:
    d, step = 3, 5
    big = unit_design("saltelli", d, 200 * step, seed=2)
    for count in (step, 7 * step, 64 * step):
        np.testing.assert_array_equal(unit_design("saltelli", d, count, seed=2), big[:count])
    for start, stop in ((0, 1), (3, 4), (4, 13), (17, 17), (998, 1000)):
        np.testing.assert_array_equal(
            unit_design("saltelli", d, 200 * step, seed=2, start=start, stop=stop),
            big[start:stop],
        )
    assert np.all((big > 0) & (big < 1))
    assert unit_design("saltelli", 0, 4, seed=0).shape == (4, 0)


def test_unit_design__saltelli_count_must_be_a_multiple_of_d_plus_2() -> None:
    with pytest.raises(ValueError, match=r"must be a multiple of 4 .* got 1001"):
        unit_design("saltelli", 2, 1001, seed=0)


def test_sample_parameters__saltelli_maps_through_the_distributions() -> None:
    sample = Sample.model_validate(
        {
            "count": 40,
            "seed": 3,
            "design": "saltelli",
            "vary": {"body.a.mass": {"normal": [2.0, 0.1]}, "body.a.angle": {"uniform": [0, 1]}},
        }
    )
    values = sample_parameters(sample)
    u = unit_design("saltelli", 2, 40, seed=3)
    np.testing.assert_array_equal(values[:, 0], ppf(sample.vary["body.a.mass"], u[:, 0]))
    np.testing.assert_array_equal(values[:, 1], u[:, 1])
    groups = values.reshape(10, 4, 2)  # rows A, AB_1, AB_2, B: the layout survives the ppf
    np.testing.assert_array_equal(groups[:, 1, 0], groups[:, 3, 0])
    np.testing.assert_array_equal(groups[:, 1, 1], groups[:, 0, 1])
    np.testing.assert_array_equal(groups[:, 2, 0], groups[:, 0, 0])
    np.testing.assert_array_equal(groups[:, 2, 1], groups[:, 3, 1])


def test_unit_design__no_columns() -> None:
    for design in ("random", "sobol", "lhs"):
        assert unit_design(design, 0, 7, seed=0).shape == (7, 0)


def test_unit_design__unknown_design() -> None:
    with pytest.raises(ValueError, match="unknown design 'grid'"):
        unit_design("grid", 1, 1, seed=0)


def test_sample_parameters__columns_in_vary_order_and_overrides() -> None:
    sample = Sample.model_validate(
        {
            "count": 64,
            "seed": 9,
            "vary": {"body.a.mass": {"uniform": [1.0, 2.0]}, "body.a.angle": {"choice": [-1.0]}},
        }
    )
    values = sample_parameters(sample)
    assert values.shape == (64, 2)
    assert np.all((values[:, 0] >= 1) & (values[:, 0] <= 2))
    np.testing.assert_array_equal(values[:, 1], -1.0)
    np.testing.assert_array_equal(sample_parameters(sample, count=8), values[:8])
    assert not np.array_equal(sample_parameters(sample, seed=10), values)
    np.testing.assert_array_equal(sample_parameters(sample, start=10, stop=20), values[10:20])
