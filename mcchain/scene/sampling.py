"""Sampling designs (unit hypercube) and distributions (inverse CDFs) for ``[sample]``.

A design fills an (n, nparam) array of uniforms strictly inside (0, 1); each column is then
mapped through its distribution's inverse CDF (:func:`ppf`). Designs:

* ``"random"``: :func:`philox_uniform` — column j of sample i is a pure function of
  (seed, i, j): Philox4x32-10 (Salmon et al., SC'11, the Random123 generator) keyed by the
  64-bit seed, counter (i mod 2³², i div 2³², j div 2, stream). So sample i's values do not
  depend on the count, on the chunking, or on how many parameters come after column j.
* ``"sobol"``: scrambled Sobol' points, ``scipy.stats.qmc.Sobol(scramble=True)`` with the
  scrambling drawn from ``numpy.random.default_rng(seed)``; point i is the i-th point of the
  sequence whatever the count (counts that are powers of 2 keep its balance properties).
  Points are moved to the centre of their 2⁻³⁰ cell so that none is exactly 0.
* ``"lhs"``: ``scipy.stats.qmc.LatinHypercube`` with ``default_rng(seed)``: one point in each
  of ``count`` strata per column, so a sample's values depend on the count (not on chunking).
* ``"saltelli"``: Saltelli's layout for Sobol' indices (first and total order), as
  ``SALib.sample.sobol.sample(problem, N, calc_second_order=False)`` lays it out. With d
  columns, point g of the ``"sobol"`` design in 2d columns (same seed) gives the base points
  A_g (its first d values) and B_g (its last d); rows come in groups of d + 2 per base point:
  A_g, AB_g1 .. AB_gd (AB_gj is A_g with column j taken from B_g), B_g. Row i belongs to group
  i // (d + 2) whatever the count, which must be a multiple of d + 2
  (:func:`~mcchain.scene.study.saltelli_count_error`). The rows are SALib's own for
  ``seed=numpy.random.default_rng(seed)``, moved to their cell centres (+2⁻³¹), and
  ``SALib.analyze.sobol.analyze(problem, Y, calc_second_order=False)`` accepts the outputs
  of all the rows in order.

Everything here is vectorised over samples: 10⁵ samples take milliseconds. SciPy is imported
on first use, so that loading a scene stays light.
"""

from __future__ import annotations

import warnings

import numpy as np

from mcchain.scene.study import Distribution, Sample, saltelli_count_error

DESIGNS = ("random", "sobol", "lhs", "saltelli")

STREAM_DESIGN = 0
"""The Philox stream (4th counter word) of the ``random`` design; other uses take others."""

_MASK32 = 0xFFFFFFFF
_PHILOX_M = (0xD2511F53, 0xCD9E8D57)
_PHILOX_W = (0x9E3779B9, 0xBB67AE85)
_SOBOL_BITS = 30


def philox4x32(
    counter: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray], key: tuple[int, int]
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Philox4x32-10 on arrays of counters (uint64 arrays holding 32-bit words).

    Args:
        counter: four arrays of 32-bit words (as uint64), broadcastable together.
        key: two 32-bit key words.

    Returns:
        The four 32-bit output words (uint64 arrays). Matches Random123's ``philox4x32_10``.
    """
    c0, c1, c2, c3 = (np.asarray(c, dtype=np.uint64) for c in counter)
    k0, k1 = key
    m0, m1 = np.uint64(_PHILOX_M[0]), np.uint64(_PHILOX_M[1])
    mask, shift = np.uint64(_MASK32), np.uint64(32)
    for r in range(10):
        if r:
            k0 = (k0 + _PHILOX_W[0]) & _MASK32
            k1 = (k1 + _PHILOX_W[1]) & _MASK32
        p0 = m0 * c0
        p1 = m1 * c2
        c0, c1, c2, c3 = (
            (p1 >> shift) ^ c1 ^ np.uint64(k0),
            p1 & mask,
            (p0 >> shift) ^ c3 ^ np.uint64(k1),
            p0 & mask,
        )
    return c0, c1, c2, c3


def philox_uniform(
    seed: int, start: int, stop: int, ncol: int, stream: int = STREAM_DESIGN
) -> np.ndarray:
    """Uniforms in (0, 1) for samples ``start:stop`` and columns ``0:ncol``.

    Entry (i, j) is ``(k + 0.5) / 2**53`` with k the 53 bits of Philox4x32-10 output
    (key = seed, counter = (i lo, i hi, j // 2, stream), words 2(j % 2), 2(j % 2) + 1):
    never exactly 0 or 1, and a pure function of (seed, i, j, stream).
    """
    if not 0 <= seed < 2**64:
        raise ValueError(f"seed must be in [0, 2**64), got {seed}")
    n = max(stop - start, 0)
    out = np.empty((n, ncol), dtype=np.float64)
    if n == 0 or ncol == 0:
        return out
    i = np.arange(start, stop, dtype=np.uint64)
    lo, hi = i & np.uint64(_MASK32), i >> np.uint64(32)
    key = (seed & _MASK32, seed >> 32)
    for block in range((ncol + 1) // 2):
        words = philox4x32(
            (lo, hi, np.full_like(lo, block), np.full_like(lo, stream & _MASK32)), key
        )
        for half in range(2):
            j = 2 * block + half
            if j >= ncol:
                break
            a, b = words[2 * half], words[2 * half + 1]
            k = ((a >> np.uint64(5)) << np.uint64(26)) | (b >> np.uint64(6))
            out[:, j] = (k.astype(np.float64) + 0.5) * 2.0**-53
    return out


def saltelli_rows(base: np.ndarray) -> np.ndarray:
    """Saltelli's rows (first and total order) from base points ``base`` (ngroup, 2d):
    (ngroup (d + 2), d), per base point A, AB_1 .. AB_d, B with A = ``base[:, :d]``,
    B = ``base[:, d:]`` and AB_j = A with column j from B (``SALib.sample.sobol.sample``)."""
    ngroup, d = base.shape[0], base.shape[1] // 2
    a, b = base[:, :d], base[:, d:]
    rows = np.empty((ngroup, d + 2, d), dtype=np.float64)
    rows[:, 0] = a
    rows[:, 1 : d + 1] = a[:, None, :]
    j = np.arange(d)
    rows[:, 1 + j, j] = b[:, j]
    rows[:, d + 1] = b
    return rows.reshape(ngroup * (d + 2), d)


def unit_design(
    design: str, ncol: int, count: int, seed: int, start: int = 0, stop: int | None = None
) -> np.ndarray:
    """Rows ``start:stop`` (default ``0:count``) of a design's (count, ncol) unit hypercube.

    All values lie strictly inside (0, 1). For ``random``, ``sobol`` and ``saltelli`` rows do
    not depend on ``count``; for ``lhs`` they do (the strata are 1/count wide). For
    ``saltelli`` the count must be a multiple of ``ncol + 2`` (ValueError otherwise).
    """
    stop = count if stop is None else stop
    if design not in DESIGNS:
        raise ValueError(f"unknown design {design!r} (expected one of: {', '.join(DESIGNS)})")
    if not 0 <= start <= stop:
        raise ValueError(f"bad sample range {start}:{stop}")
    n = stop - start
    if design == "random":
        return philox_uniform(seed, start, stop, ncol)
    if design == "saltelli":
        reason = saltelli_count_error(ncol, count)
        if reason is not None:
            raise ValueError(f"count: {reason}")
        step = ncol + 2
        first, last = start // step, -(-stop // step)  # the groups rows start:stop fall in
        base = unit_design("sobol", 2 * ncol, last, seed, first, last)
        return saltelli_rows(base)[start - first * step : stop - first * step]
    if ncol == 0 or n == 0:
        return np.empty((n, ncol), dtype=np.float64)
    return _cached_design(design, ncol, count, seed, start, stop)


def _cached_design(
    design: str, ncol: int, count: int, seed: int, start: int, stop: int
) -> np.ndarray:
    """:func:`_scipy_design`, kept in mcchain's cache (``designs``) under its arguments and
    scipy's version: importing scipy.stats costs about 1 s, far more than the design itself,
    and a rerun of the same study draws the same points. A cache that cannot be read or
    written is skipped; the values are the same either way (float64 saved exactly)."""
    import hashlib
    import os
    import tempfile

    import scipy

    from mcchain.compiled.caches import mcchain_cache

    rows = count if design == "lhs" else 0  # LHS strata depend on the count
    key = f"{design} {ncol} {rows} {seed} {start} {stop} scipy {scipy.__version__}"
    folder = mcchain_cache("designs")
    path = folder / (hashlib.sha256(key.encode()).hexdigest()[:24] + ".npy")
    try:
        cached = np.load(path, allow_pickle=False)
        if cached.shape == (stop - start, ncol) and cached.dtype == np.float64:
            return cached
    except (OSError, ValueError):
        pass
    values = _scipy_design(design, ncol, count, seed, start, stop)
    try:
        fd, tmp = tempfile.mkstemp(dir=folder, suffix=".tmp")
        with os.fdopen(fd, "wb") as fh:
            np.save(fh, values, allow_pickle=False)
        os.replace(tmp, path)
    except OSError:
        pass
    return values


def _scipy_design(
    design: str, ncol: int, count: int, seed: int, start: int, stop: int
) -> np.ndarray:
    """Rows ``start:stop`` of scipy's scrambled Sobol' or Latin hypercube design."""
    from scipy.stats import qmc

    n = stop - start
    rng = np.random.default_rng(seed)
    if design == "sobol":
        if stop > 2**_SOBOL_BITS:
            raise ValueError(f"sobol design: at most 2**{_SOBOL_BITS} samples")
        sobol = qmc.Sobol(ncol, scramble=True, bits=_SOBOL_BITS, rng=rng)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # "balance properties ... power of 2"
            if start:
                sobol.fast_forward(start)
            u = sobol.random(n)
        # Scrambled points are multiples of 2**-30 in [0, 1): use the cell centres.
        return u + 2.0 ** -(_SOBOL_BITS + 1)
    u = qmc.LatinHypercube(ncol, rng=rng).random(count)[start:stop]
    return np.clip(u, 2.0**-54, 1.0 - 2.0**-53)


def _standard_normal_ppf(u: np.ndarray) -> np.ndarray:
    """Φ⁻¹(u) element by element, u in (0, 1): the standard library's (Wichura's AS241,
    within 6 ulp of ``scipy.special.ndtri``), 0.25 µs per value. Importing scipy.special
    took 0.15-0.2 s of every warm run, more than a million values cost."""
    from statistics import NormalDist

    return np.asarray(np.frompyfunc(NormalDist().inv_cdf, 1, 1)(u), dtype=np.float64)


def ppf(dist: Distribution, u: np.ndarray) -> np.ndarray:
    """Map uniforms ``u`` in (0, 1) to the distribution's values (inverse CDF).

    uniform [lo, hi]: lo + u (hi - lo); normal [mean, std]: mean + std Φ⁻¹(u); lognormal
    [mu, sigma]: exp(mu + sigma Φ⁻¹(u)); truncnormal [mean, std, lo, hi]: scipy.stats.truncnorm
    (clipped to [lo, hi] against rounding); choice [v...]: v[floor(u n)]. With ``within =
    [low, high]``: the same distribution truncated there, F⁻¹(F(low) + u (F(high) −
    F(low))) (choice: the values inside, each equally likely), clipped to [low, high].
    """
    u = np.asarray(u, dtype=np.float64)
    within = getattr(dist, "within", None)
    if within is None:
        return _ppf(dist.kind, dist.args, u)
    low, high = within
    if dist.kind == "choice":
        inside = [v for v in dist.args if low <= v <= high]
        return _ppf("choice", inside, u)
    lo, hi = cdf(dist.kind, dist.args, np.array([low, high], dtype=np.float64))
    x = _ppf(dist.kind, dist.args, lo + u * (hi - lo))
    return np.clip(x, low, high)


def cdf(kind: str, args: list[float], x: np.ndarray) -> np.ndarray:
    """The cumulative distribution function of a continuous distribution (``within``
    ignored), for :func:`ppf` and the what-if weights."""
    x = np.asarray(x, dtype=np.float64)
    if kind == "uniform":
        lo, hi = args
        return np.clip((x - lo) / (hi - lo), 0.0, 1.0) if hi > lo else (x >= lo).astype(float)
    from scipy import stats

    if kind == "normal":
        return np.asarray(stats.norm.cdf(x, loc=args[0], scale=args[1]))
    if kind == "lognormal":
        with np.errstate(divide="ignore"):
            z = np.log(np.maximum(x, 0.0))
        return np.asarray(stats.norm.cdf(z, loc=args[0], scale=args[1]))
    if kind == "truncnormal":
        mean, std, lo, hi = args
        a, b = (lo - mean) / std, (hi - mean) / std
        return np.asarray(stats.truncnorm.cdf(x, a, b, loc=mean, scale=std))
    raise ValueError(f"no cumulative distribution function for {kind!r}")


def _ppf(kind: str, a: list[float], u: np.ndarray) -> np.ndarray:
    if kind == "uniform":
        return a[0] + u * (a[1] - a[0])
    if kind == "choice":
        values = np.asarray(a, dtype=np.float64)
        k = np.minimum((u * len(values)).astype(np.int64), len(values) - 1)
        return values[k]
    if kind in ("normal", "lognormal"):
        z = _standard_normal_ppf(u)
        return a[0] + a[1] * z if kind == "normal" else np.exp(a[0] + a[1] * z)
    if kind == "truncnormal":
        from scipy import stats

        mean, std, lo, hi = a
        x = stats.truncnorm.ppf(u, (lo - mean) / std, (hi - mean) / std, loc=mean, scale=std)
        return np.clip(x, lo, hi)
    raise ValueError(f"unknown distribution {kind!r}")


def sample_parameters(
    sample: Sample,
    count: int | None = None,
    seed: int | None = None,
    start: int = 0,
    stop: int | None = None,
) -> np.ndarray:
    """The sampled values, (stop - start, nparam) float64, columns in ``vary`` order.

    ``count``/``seed`` default to the section's; ``start:stop`` (default ``0:count``) picks a
    range of samples, identical to the same rows of the full draw.
    """
    count = sample.count if count is None else count
    seed = sample.seed if seed is None else seed
    dists = list(sample.vary.values())
    u = unit_design(sample.design, len(dists), count, seed, start, stop)
    values = np.empty_like(u)
    for j, dist in enumerate(dists):
        values[:, j] = ppf(dist, u[:, j])
    return values
