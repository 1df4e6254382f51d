"""Damped modes: the constrained quadratic eigenproblem (s² M + s C + K) z = 0, B z = 0.

In the mass-normalised undamped modal basis Z (Z M Zᵀ = I, Z K Zᵀ = diag p², rows spanning
the null space of B) it is the f × f problem (s² I + s D + diag p²) ξ = 0, D = Z C Zᵀ
(:func:`mcchain.kernels.statics.modal_damping_batch`), solved here through its 2f × 2f
companion form [[0, I], [−diag p², −D]] by NumPy's batched ``eig`` (LAPACK geev).

Each mode is one pair of roots (s₁, s₂), reported as

* ``damped_omega`` = |Im s| (rad/s): the damped pulsation, 0 for a pair of real roots;
* ``damping_ratio`` ζ = −(s₁ + s₂) / (2 √(s₁ s₂)): −Re s/|s| for a conjugate pair (0 ≤ ζ < 1),
  ≥ 1 for two negative real roots (an overdamped mode: 1 DOF gives s = −ζp ± p√(ζ² − 1)),
  +inf for a damped zero mode (roots 0 and −d), 0 for an undamped one (0, 0), and NaN where
  s₁ s₂ < 0: a root s > 0 (an unstable mode, ``omega`` < 0).

Pairing: a conjugate pair is one mode; real roots are paired greedily, smallest |s| first,
each with the remaining real root whose eigenvector ξ is the most parallel to its own (the two
roots of a decoupled mode share ξ exactly). Order: ascending signed |s| = sign(s₁s₂)√|s₁s₂|,
which is the undamped order of ``omega`` (p = |s| for an undamped mode) unless damping moves
one mode's |s| past another's. A mode the dampers do not touch (its row of D is zero to
round-off) keeps its undamped roots ±ip exactly; a sample without damping reports
``damped_omega`` = max(``omega``, 0) and ζ = 0 (NaN where ``omega`` < 0), bit for bit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

EPS = float(np.finfo(np.float64).eps)
UNTOUCHED_RTOL = 1e3 * EPS
"""A mode whose row of D is below this × max |D| is not damped (round-off of D = Z C Zᵀ)."""
ZERO_ROOT_RTOL = 1e3 * EPS
"""A root below this × the sample's largest |s| is an exact zero (round-off of geev)."""


@dataclass(frozen=True)
class DampedModes:
    """Damped modes of a batch: ``damped_omega`` (rad/s) and ``damping_ratio`` (1), both
    (nsample, nmode), NaN where the undamped modes failed."""

    damped_omega: np.ndarray
    damping_ratio: np.ndarray


def damped_modes(omega: np.ndarray, damping: np.ndarray | None) -> DampedModes:
    """Damped modes from the undamped signed pulsations and the modal damping.

    Args:
        omega: (nsample, nmode) signed p (rad/s) of :func:`~mcchain.solvers.statics.solve_modes`.
        damping: (nsample, nmode, nmode) modal damping D (1/s), or None: no dampers.
    """
    omega = np.asarray(omega, dtype=np.float64)
    nsample, nmode = omega.shape
    damped_omega = np.full((nsample, nmode), np.nan)
    ratio = np.full((nsample, nmode), np.nan)
    finite = np.isfinite(omega).all(axis=1)
    if damping is None:
        undamped = finite
    else:
        finite &= np.isfinite(damping).all(axis=(1, 2))
        undamped = finite & (damping == 0.0).all(axis=(1, 2))
    damped_omega[undamped] = np.maximum(omega[undamped], 0.0)
    ratio[undamped] = np.where(omega[undamped] >= 0.0, 0.0, np.nan)
    coupled = np.flatnonzero(finite & ~undamped)
    if coupled.size == 0 or damping is None:
        return DampedModes(damped_omega, ratio)
    p2 = np.sign(omega[coupled]) * omega[coupled] ** 2
    D = damping[coupled]
    A = companion(p2, D)
    roots = np.linalg.eigvals(A)
    scale = np.abs(D).max(axis=(1, 2))
    untouched = (np.abs(D).max(axis=2) <= UNTOUCHED_RTOL * scale[:, None]).any(axis=1)
    # the common case needs no eigenvectors: every mode touched by a damper and underdamped
    simple = ~untouched & (roots.imag != 0.0).all(axis=1)
    if simple.any():
        upper = _upper_roots(roots[simple], nmode)
        _store(coupled[simple], *_modes(upper, np.conj(upper)), damped_omega, ratio)
    # real roots, every mode touched: batched eig, roots paired by eigenvector
    full = ~simple & ~untouched
    if full.any():
        full_roots, vectors = np.linalg.eig(A[full])
        _store(coupled[full], *_modes(*_pairs(full_roots, vectors[:, :nmode])), damped_omega, ratio)
    for k in np.flatnonzero(untouched):
        damped_omega[coupled[k]], ratio[coupled[k]] = _deflated(omega[coupled[k]], D[k])
    return DampedModes(damped_omega, ratio)


def companion(p2: np.ndarray, damping: np.ndarray) -> np.ndarray:
    """[[0, I], [−diag p², −D]] for a batch: p2 (..., f), damping (..., f, f) -> (..., 2f, 2f)."""
    f = p2.shape[-1]
    A = np.zeros((*p2.shape[:-1], 2 * f, 2 * f))
    A[..., :f, f:] = np.eye(f)
    A[..., f:, f:] = -damping
    A[..., f:, :f] = -p2[..., :, None] * np.eye(f)
    return A


def _store(
    rows: np.ndarray,
    key: np.ndarray,
    damped: np.ndarray,
    zeta: np.ndarray,
    damped_omega_out: np.ndarray,
    ratio_out: np.ndarray,
) -> None:
    """Write modes (len(rows), f) into ``rows`` of the outputs in ascending ``key``."""
    order = np.argsort(key, axis=1, kind="stable")
    damped_omega_out[rows] = np.take_along_axis(damped, order, 1)
    ratio_out[rows] = np.take_along_axis(zeta, order, 1)


def _upper_roots(roots: np.ndarray, count: int) -> np.ndarray:
    """The ``count`` roots of largest imaginary part of each row (..., 2f)."""
    return np.take_along_axis(roots, np.argsort(-roots.imag, axis=-1, kind="stable"), -1)[
        ..., :count
    ]


def _modes(s1: np.ndarray, s2: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(signed |s|, damped_omega, damping_ratio) of modes with roots s1, s2 (any shape)."""
    product = (s1 * s2).real
    total = (s1 + s2).real
    root = np.sqrt(np.abs(product))
    with np.errstate(divide="ignore", invalid="ignore"):
        zeta = np.where(product > 0.0, -total / (2.0 * root), np.nan)
    zero = (product == 0.0) & (total <= 0.0)  # a zero mode: damped (0, −d) or not (0, 0)
    zeta = np.where(zero, np.where(total < 0.0, np.inf, 0.0), zeta)
    return np.sign(product) * root, np.abs(s1.imag), zeta


def _pairs(roots: np.ndarray, shapes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The f roots pairs (s1, s2), each (nsample, f), of a batch of companion solutions.

    Args:
        roots: (nsample, 2f); shapes: (nsample, f, 2f) their eigenvectors ξ by column.
    """
    nsample, f = shapes.shape[:2]
    snap = np.abs(roots) <= ZERO_ROOT_RTOL * np.abs(roots).max(axis=1, keepdims=True)
    roots = np.where(snap, 0.0, roots)
    real = roots.imag == 0.0
    nreal = real.sum(axis=1)
    s1 = np.empty((nsample, f), dtype=complex)
    s2 = np.empty((nsample, f), dtype=complex)
    for count in np.unique(nreal):
        rows = np.flatnonzero(nreal == count)
        ncomplex = f - count // 2
        upper = _upper_roots(roots[rows], ncomplex)
        s1[rows, :ncomplex] = upper
        s2[rows, :ncomplex] = np.conj(upper)
        # real roots by |s|, each (smallest first) paired with the most parallel remaining ξ
        order = np.argsort(np.where(real[rows], np.abs(roots[rows]), np.inf), axis=1)
        order = order[:, :count]
        values = np.take_along_axis(roots[rows], order, 1)
        xi = np.take_along_axis(shapes[rows], order[:, None, :], 2)
        xi = xi / np.linalg.norm(xi, axis=1, keepdims=True)
        cosine = np.abs(np.einsum("sik,sil->skl", xi.conj(), xi))
        free = np.ones((rows.size, count), dtype=bool)
        pick = np.arange(rows.size)
        for slot in range(ncomplex, f):
            first = np.argmax(free, axis=1)
            free[pick, first] = False
            second = np.argmax(np.where(free, cosine[pick, first], -1.0), axis=1)
            free[pick, second] = False
            s1[rows, slot] = values[pick, first]
            s2[rows, slot] = values[pick, second]
    return s1, s2


def _deflated(omega: np.ndarray, D: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(damped_omega, damping_ratio) of one sample with modes no damper touches: those keep
    their undamped roots ±ip exactly, the others solve their own quadratic problem."""
    row = np.abs(D).max(axis=1)
    kept = np.flatnonzero(row > UNTOUCHED_RTOL * row.max())
    key = omega.copy()
    damped_omega = np.maximum(omega, 0.0)
    ratio = np.where(omega >= 0.0, 0.0, np.nan)
    p2 = np.sign(omega[kept]) * omega[kept] ** 2
    roots, vectors = np.linalg.eig(companion(p2, D[np.ix_(kept, kept)]))
    modes = _modes(*_pairs(roots[None], vectors[None, : kept.size]))
    key[kept], damped_omega[kept], ratio[kept] = (m[0] for m in modes)
    order = np.argsort(key, kind="stable")
    return damped_omega[order], ratio[order]
