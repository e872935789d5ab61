"""The reflection prefilter kernel of the split-sum method (Karis 2013), whose roughness the
blur table gives: GGX normals around the lookup direction d with N = V = R = d, light
directions l = reflect(d, h) weighted by N.L, so over l the kernel is

    k(l; d, alpha) = D(h) max(d.l, 0) / (4 N(alpha)),   h = half vector of d and l.

In u = the GGX sampling coordinate of h (tan theta_h = alpha sqrt(u / (1 - u)), the CDF of
D(h) cos theta_h), d.l = cos 2 theta_h is the rational c(u) = (1 - (1 + a^2) u) / (1 - (1 - a^2) u)
on [0, 1 / (1 + a^2)], so the kernel's moments are one-dimensional integrals of powers of c.
"""

from __future__ import annotations

import functools

import numpy as np

#: Largest roughness the blur table gives: a transmitted lobe wider than the alpha = BLUR_MAX
#: kernel is stored as BLUR_MAX (the kernel's spread saturates as alpha grows, see docs/lut.md).
BLUR_MAX = 4.0
#: Gauss-Legendre nodes of the moment integrals (the integrand is a smooth rational function).
QUADRATURE_NODES = 96
#: Roughness nodes, uniform in sqrt(alpha), of the table that inverts the mean cosine.
INVERSION_NODES = 4097


@functools.cache
def _gauss_legendre() -> tuple[np.ndarray, np.ndarray]:
    """The QUADRATURE_NODES-point Gauss-Legendre rule on [-1, 1] (computed once: 25 ms)."""
    return np.polynomial.legendre.leggauss(QUADRATURE_NODES)


def _rule(alpha: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Legendre weights in u (du, ..., QUADRATURE_NODES) and c = d.l at the nodes."""
    a2 = np.asarray(alpha, dtype=np.float64)[..., None] ** 2
    x, w = _gauss_legendre()
    u_max = 1.0 / (1.0 + a2)
    u = 0.5 * (x + 1.0) * u_max
    return 0.5 * u_max * w, (1.0 - (1.0 + a2) * u) / (1.0 - (1.0 - a2) * u)


def kernel_moments(alpha: np.ndarray, powers: tuple[int, ...] = (1, 2)) -> np.ndarray:
    """E_k[(d.l)^p] for each power p: shape (len(powers), *alpha.shape). alpha = 0 gives 1."""
    w, c = _rule(alpha)
    norm = np.sum(w * c, axis=-1)
    return np.stack([np.sum(w * c ** (p + 1), axis=-1) / norm for p in powers])


def normalisation(alpha: np.ndarray) -> np.ndarray:
    """N(alpha) = integral of max(d.l, 0) D(h) cos theta_h dh: the kernel's unnormalised mass."""
    w, c = _rule(alpha)
    return np.sum(w * c, axis=-1)


@functools.cache
def _inversion() -> tuple[np.ndarray, np.ndarray]:
    """(sqrt(1 - mean cosine), alpha) at INVERSION_NODES roughness values, both increasing:
    sqrt(1 - E_k[d.l]) is nearly proportional to alpha at small alpha, so linear
    interpolation in it is accurate there."""
    alpha = np.linspace(0.0, np.sqrt(BLUR_MAX), INVERSION_NODES) ** 2
    return np.sqrt(np.maximum(1.0 - kernel_moments(alpha, (1,))[0], 0.0)), alpha


def equivalent_alpha(mean_cos: np.ndarray) -> np.ndarray:
    """The kernel roughness whose mean cosine E_k[d.l] equals mean_cos (clamped to
    [0, BLUR_MAX]): the blur table's matching criterion."""
    spread, alpha = _inversion()
    return np.interp(np.sqrt(np.maximum(1.0 - np.asarray(mean_cos), 0.0)), spread, alpha)
