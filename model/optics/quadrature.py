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


@lru_cache(maxsize=64)
def _gauss(n: int) -> tuple[np.ndarray, np.ndarray]:
    return np.polynomial.legendre.leggauss(n)


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


def splittable(center: np.ndarray, half_angle_rad: float, axis: np.ndarray) -> bool:
    """Whether split_cap_rule serves caps of this half-angle about centers (..., 3) cut by
    circles about axis (..., 3): each axis and its antipode lie at least two half-angles
    from the cap (nearer, the coordinates about the axis bunch up inside the cap)."""
    cos_t = np.sum(center * axis, axis=-1)
    return bool(np.all(np.abs(cos_t) <= np.cos(2.0 * half_angle_rad)))


def split_cap_rule(
    center: np.ndarray, half_angle_rad: float, axis: np.ndarray, levels: np.ndarray,
    n_across: int, n_along: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Nodes (N, K, 3) and solid-angle weights (N, K) of a rule on the caps of half-angle
    half_angle_rad about centers (N, 3), cut along the circles {w: axis . w = level} (axis
    (N, 3), levels (N, L)): a piecewise-smooth integrand whose jumps or kinks lie on those
    circles converges spectrally, where the polar rule of cap_rule converges only algebraically.

    Coordinates u = axis . w (across the circles) and v, the azimuth about the axis (along
    them), so d omega = du dv. The cap spans u in [cos(t + beta), cos(t - beta)] (t: the
    centre's angle from the axis), cut at each level into pieces; on each, u = m + h sin s
    (Gauss-Legendre, n_across nodes, in s), which absorbs the square-root ends of the arc
    length where the rim or a level is tangent to the circle of constant u; along it,
    Gauss-Legendre with n_along nodes over the arc |v| <= V(u) inside the cap. A level
    outside the cap makes a piece of zero weight. Needs `splittable` caps."""
    x_u, w_u = _gauss(int(n_across))
    x_v, w_v = _gauss(int(n_along))
    center, axis = np.atleast_2d(center), np.atleast_2d(axis)
    cos_t = np.clip(np.sum(center * axis, axis=-1), -1.0, 1.0)
    t = np.arccos(cos_t)
    sin_t = np.sin(t)
    e1 = center - cos_t[:, None] * axis
    e1 /= np.linalg.norm(e1, axis=-1, keepdims=True)
    e2 = np.cross(axis, e1)
    lo, hi = np.cos(t + half_angle_rad), np.cos(t - half_angle_rad)
    cuts = np.clip(np.atleast_2d(levels), lo[:, None], hi[:, None])
    breaks = np.sort(np.concatenate([lo[:, None], cuts, hi[:, None]], axis=1), axis=1)
    mid = 0.5 * (breaks[:, 1:] + breaks[:, :-1])  # (N, P)
    half = 0.5 * (breaks[:, 1:] - breaks[:, :-1])
    s = 0.5 * np.pi * x_u
    u = mid[..., None] + half[..., None] * np.sin(s)  # (N, P, n_across)
    du = half[..., None] * (0.5 * np.pi * np.cos(s)) * w_u
    r = np.sqrt(np.clip(1.0 - u * u, 0.0, None))
    cos_arc = (np.cos(half_angle_rad) - u * cos_t[:, None, None]) / np.maximum(
        r * sin_t[:, None, None], 1e-300)
    arc = np.arccos(np.clip(cos_arc, -1.0, 1.0))  # V(u): half the arc inside the cap
    v = arc[..., None] * x_v  # (N, P, n_across, n_along)
    n = len(center)
    nodes = (u[..., None, None] * axis[:, None, None, None, :]
             + (r[..., None] * np.cos(v))[..., None] * e1[:, None, None, None, :]
             + (r[..., None] * np.sin(v))[..., None] * e2[:, None, None, None, :])
    weights = (du * arc)[..., None] * w_v
    return nodes.reshape(n, -1, 3), weights.reshape(n, -1)
