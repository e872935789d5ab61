"""The reflection prefilter kernel of the split-sum method (Karis 2013), whose roughness the
blur table gives: GGX normals around the lookup direction d with N = V = R = d, light
directions l = reflect(d, h) weighted by N.L, so over l the kernel is

    k(l; d, alpha) = D(h) max(d.l, 0) / (4 N(alpha)),   h = half vector of d and l.

In u = the GGX sampling coordinate of h (tan theta_h = alpha sqrt(u / (1 - u)), the CDF of
D(h) cos theta_h), the kernel's moments are one-dimensional integrals of powers of
d.l = cos 2 theta_h = (1 - tan^2) / (1 + tan^2) over tan theta_h <= 1.
"""

from __future__ import annotations

import functools

import numpy as np

#: Largest roughness the blur table gives: a transmitted lobe wider than the alpha = BLUR_MAX
#: kernel is stored as BLUR_MAX (the kernel's spread saturates as alpha grows, see docs/lut.md).
BLUR_MAX = 4.0
#: Gauss-Legendre nodes of each of the two pieces of the moment integrals (core and tail).
QUADRATURE_NODES = 96
#: Roughness nodes, uniform in sqrt(alpha), of the table that inverts the mean cosine.
INVERSION_NODES = 4097


@functools.cache
def _gauss_legendre() -> tuple[np.ndarray, np.ndarray]:
    """The QUADRATURE_NODES-point Gauss-Legendre rule on [-1, 1] (computed once: 25 ms)."""
    return np.polynomial.legendre.leggauss(QUADRATURE_NODES)


def _rule(alpha: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Weights in u (du, ..., 2 QUADRATURE_NODES), c = d.l and 1 - c at the nodes.

    In r = tan(theta_h) / alpha, du = 2 r / (1 + r^2)^2 dr: Gauss-Legendre in r on the core
    [0, min(1, 1 / alpha)] and in ln r on the tail up to r = 1 / alpha (theta_h = 45 degrees),
    whose share of 1 - c spreads evenly over the scales between alpha and 1 (it grows like
    alpha^2 ln(1 / alpha)). 1 - c = 2 t^2 / (1 + t^2) with t = alpha r, exact where c rounds to 1.
    """
    a = np.maximum(np.asarray(alpha, dtype=np.float64), 1e-150)[..., None]
    x, w = _gauss_legendre()
    core_end = np.minimum(1.0, 1.0 / a)
    r_core = 0.5 * (x + 1.0) * core_end
    w_core = 0.5 * core_end * w * 2.0 * r_core / (1.0 + r_core**2) ** 2
    log_start, log_end = np.log(core_end), np.log(1.0 / a)
    r_tail = np.exp(log_start + 0.5 * (x + 1.0) * (log_end - log_start))
    w_tail = 0.5 * (log_end - log_start) * w * 2.0 / (1.0 / r_tail + r_tail) ** 2
    t = a * np.concatenate([r_core + 0 * a, r_tail], axis=-1)
    one_minus_c = 2.0 * t * t / (1.0 + t * t)
    return np.concatenate([w_core + 0 * a, w_tail], axis=-1), 1.0 - one_minus_c, one_minus_c


def kernel_spreads(alpha: np.ndarray) -> np.ndarray:
    """(E_k[1 - d.l], E_k[1 - (d.l)^2]) of the kernel: shape (2, *alpha.shape), written
    without cancellation so that tiny kernels keep their digits; alpha = 0 gives 0."""
    w, c, one_minus_c = _rule(alpha)
    norm = np.sum(w * c, axis=-1)
    return np.stack([np.sum(w * c * one_minus_c, axis=-1) / norm,
                     np.sum(w * c * one_minus_c * (1.0 + c), axis=-1) / norm])


def normalisation(alpha: np.ndarray) -> np.ndarray:
    """N(alpha) = integral of max(d.l, 0) D(h) cos theta_h dh: the kernel's unnormalised mass."""
    w, c, _ = _rule(alpha)
    return np.sum(w * c, axis=-1)


@functools.cache
def _inversion() -> tuple[np.ndarray, np.ndarray]:
    """(sqrt(1 - E_k[d.l]), alpha) at INVERSION_NODES roughness values, both increasing:
    sqrt(1 - E_k[d.l]) is nearly proportional to alpha at small alpha, so linear
    interpolation in it is accurate there."""
    alpha = np.linspace(0.0, np.sqrt(BLUR_MAX), INVERSION_NODES) ** 2
    return np.sqrt(kernel_spreads(alpha)[0]), alpha


def equivalent_alpha(one_minus_cos: np.ndarray) -> np.ndarray:
    """The kernel roughness whose 1 - E_k[d.l] equals one_minus_cos (clamped to
    [0, BLUR_MAX]): the blur table's matching criterion, equal mean cosines."""
    spread, alpha = _inversion()
    return np.interp(np.sqrt(np.maximum(np.asarray(one_minus_cos, dtype=np.float64), 0.0)),
                     spread, alpha)
