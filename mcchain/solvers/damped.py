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
    roots = np.linalg.eigvals(companion(p2, D))
    # the common case, vectorised: every mode touched by a damper and underdamped
    scale = np.abs(D).max(axis=(1, 2))
    untouched = (np.abs(D).max(axis=2) <= UNTOUCHED_RTOL * scale[:, None]).any(axis=1)
    simple = ~untouched & (roots.imag != 0.0).all(axis=1)
    if simple.any():
        upper = np.take_along_axis(roots[simple], np.argsort(-roots[simple].imag, axis=1), 1)
        upper = upper[:, :nmode]
        upper = np.take_along_axis(upper, np.argsort(np.abs(upper), axis=1, kind="stable"), 1)
        damped_omega[coupled[simple]] = upper.imag
        ratio[coupled[simple]] = -upper.real / np.abs(upper)
    for k in np.flatnonzero(~simple):
        damped_omega[coupled[k]], ratio[coupled[k]] = _one_sample(omega[coupled[k]], D[k])
    return DampedModes(damped_omega, ratio)


def companion(p2: np.ndarray, damping: np.ndarray) -> np.ndarray:
    """[[0, I], [−diag p², −D]] for a batch: p2 (..., f), damping (..., f, f) -> (..., 2f, 2f)."""
    f = p2.shape[-1]
    A = np.zeros((*p2.shape[:-1], 2 * f, 2 * f))
    A[..., :f, f:] = np.eye(f)
    A[..., f:, f:] = -damping
    A[..., f:, :f] = -p2[..., :, None] * np.eye(f)
    return A


def _one_sample(omega: np.ndarray, D: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(damped_omega, damping_ratio) of one sample with real roots or untouched modes."""
    nmode = omega.shape[0]
    key = np.empty(nmode)
    damped_omega = np.empty(nmode)
    ratio = np.empty(nmode)
    row = np.abs(D).max(axis=1)
    untouched = row <= UNTOUCHED_RTOL * row.max()
    # modes no damper touches: their undamped roots ±ip, exactly
    key[untouched] = omega[untouched]
    damped_omega[untouched] = np.maximum(omega[untouched], 0.0)
    ratio[untouched] = np.where(omega[untouched] >= 0.0, 0.0, np.nan)
    kept = np.flatnonzero(~untouched)
    p2 = np.sign(omega[kept]) * omega[kept] ** 2
    roots, vectors = np.linalg.eig(companion(p2, D[np.ix_(kept, kept)]))
    roots = np.where(np.abs(roots) <= ZERO_ROOT_RTOL * np.abs(roots).max(), 0.0, roots)
    pairs = [(root, np.conj(root)) for root in roots if root.imag > 0.0]
    real = [int(i) for i in np.argsort(np.abs(roots)) if roots[i].imag == 0.0]
    shapes = vectors[: kept.size]  # ξ of each root, by column
    while real:
        first = real.pop(0)
        a = shapes[:, first] / np.linalg.norm(shapes[:, first])
        cosines = [abs(np.vdot(a, shapes[:, j])) / np.linalg.norm(shapes[:, j]) for j in real]
        second = real.pop(int(np.argmax(cosines)))
        pairs.append((roots[first], roots[second]))
    for slot, (s1, s2) in zip(kept, pairs, strict=True):
        product = float((s1 * s2).real)
        total = float((s1 + s2).real)
        key[slot] = np.sign(product) * np.sqrt(abs(product))
        damped_omega[slot] = abs(s1.imag)
        if product > 0.0:
            ratio[slot] = -total / (2.0 * np.sqrt(product))
        elif product == 0.0 and total <= 0.0:
            ratio[slot] = np.inf if total < 0.0 else 0.0
        else:
            ratio[slot] = np.nan
    order = np.argsort(key, kind="stable")
    return damped_omega[order], ratio[order]
