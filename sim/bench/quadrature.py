"""Quadrature over a spherical cap (a detector aperture, a divergent beam's cone of directions).

Product rule in polar coordinates about the cap's centre: Gauss-Legendre in the polar angle
rho in [0, beta] with the sin(rho) area element, and the periodic trapezoid rule (spectrally
accurate) in the azimuth phi. Order 0 is the one-point formula: the centre times the cap's
solid angle 2 pi (1 - cos beta).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np


def cap_solid_angle(half_angle_rad: float) -> float:
    """Solid angle of a cap of the given half-angle, sr (written stably for small angles)."""
    return 4.0 * np.pi * np.sin(0.5 * half_angle_rad) ** 2


def azimuth_count(n_radial: int) -> int:
    """Azimuthal nodes used with n_radial polar nodes (the rim needs about 2 pi / pi as many)."""
    return 1 if n_radial == 0 else 2 * n_radial + 2


@lru_cache(maxsize=64)
def _unit_rule(n_radial: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(rho fraction in [0, 1], phi, weight without the beta and sin factors) per node."""
    if n_radial == 0:
        return np.zeros(1), np.zeros(1), np.ones(1)
    x, w = np.polynomial.legendre.leggauss(n_radial)
    m = azimuth_count(n_radial)
    t, phi = 0.5 * (x + 1.0), 2.0 * np.pi * (np.arange(m) + 0.5) / m
    frac = np.repeat(t, m)
    weight = np.repeat(0.5 * w, m) * (2.0 * np.pi / m)
    return frac, np.tile(phi, n_radial), weight


def node_count(n_radial: int) -> int:
    """Number of directions a cap rule of this order evaluates."""
    return n_radial * azimuth_count(n_radial) if n_radial else 1


def orthonormal_basis(c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors (..., 3) completing unit vectors c (..., 3) to a right-handed frame."""
    helper = np.where(np.abs(c[..., 2:3]) < 0.9, [0.0, 0.0, 1.0], [1.0, 0.0, 0.0])
    e1 = np.cross(helper, c)
    e1 /= np.linalg.norm(e1, axis=-1, keepdims=True)
    return e1, np.cross(c, e1)


def cap_rule(
    center: np.ndarray, half_angle_rad: float, n_radial: int
) -> tuple[np.ndarray, np.ndarray]:
    """Nodes (..., K, 3) and solid-angle weights (K,) of the order-n_radial rule on the cap of
    half-angle half_angle_rad about unit vectors center (..., 3); weights sum to the cap's
    solid angle to the rule's accuracy (exactly for order 0)."""
    frac, phi, weight = _unit_rule(int(n_radial))
    if n_radial == 0 or half_angle_rad == 0.0:
        return center[..., None, :], np.array([cap_solid_angle(half_angle_rad)])
    rho = frac * half_angle_rad
    e1, e2 = orthonormal_basis(center)
    c, s = np.cos(rho)[:, None], np.sin(rho)[:, None]
    nodes = (c * center[..., None, :] + s * np.cos(phi)[:, None] * e1[..., None, :]
             + s * np.sin(phi)[:, None] * e2[..., None, :])
    return nodes, weight * half_angle_rad * np.sin(rho)
