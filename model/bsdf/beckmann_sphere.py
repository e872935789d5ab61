"""Visible normals of the unit-roughness Beckmann surface seen from any direction on the sphere,
by inversion of the slope CDF in log form (the random walk's sampler; Beckmann.sample_visible
covers the upper hemisphere with an inversion in the erf variable)."""

from __future__ import annotations

import numpy as np
from scipy.special import erfc, erfcx, ndtri

from model.bsdf.constants import SQRT_PI


def _log_cdf(x: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """log F(x), F(x) = int_{-inf}^x (mu - t) exp(-t^2)/sqrt(pi) dt (x <= mu); stable tails."""
    neg = x <= 0.0
    xn = np.where(neg, x, 0.0)
    xp = np.where(neg, 0.0, x)
    with np.errstate(divide="ignore", invalid="ignore"):
        left = -xn * xn + np.log(mu * erfcx(-xn) + 1.0 / SQRT_PI)
        right = np.log(mu * erfc(-xp) + np.exp(-xp * xp) / SQRT_PI)
    return np.where(neg, left, right) - np.log(2.0)


def _visible_slope(mu: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Slope x < mu with density proportional to (mu - x) exp(-x^2), by inversion of its CDF.

    log F is concave (the density is log-concave), so Newton's method started left of the root
    climbs to it monotonically; the start comes from F(x) <= exp(-x^2)(max(mu,0) + 1/sqrt(pi))/2.
    """
    target = np.log(u) + _log_cdf(mu, mu)
    bound = np.log(0.5 * (np.maximum(mu, 0.0) + 1.0 / SQRT_PI)) - target
    x = np.minimum(-np.sqrt(np.maximum(bound, 0.0)), mu)
    for _ in range(60):
        g = _log_cdf(x, mu)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            log_f = np.log(np.maximum(mu - x, 0.0)) - x * x - np.log(SQRT_PI)
            step = (target - g) / np.exp(log_f - g)
        step = np.where(np.isfinite(step) & (step > 0.0), step, 0.0)
        x = np.minimum(x + step, mu)
        if np.all(step <= 1e-13 * (1.0 + np.abs(x))):
            break
    return x


def vertical_slopes(u1: np.ndarray, u2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Visible slopes of the alpha = 1 Beckmann surface seen from straight above: every facet
    is seen as its slope density exp(-x^2 - y^2) / pi says, so the slope's squared radius is
    Exp(1) and its azimuth uniform (x = r cos 2 pi u2, y = r sin 2 pi u2, r^2 = -log(1 - u1))."""
    r = np.sqrt(-np.log1p(-u1))
    return r * np.cos(2.0 * np.pi * u2), r * np.sin(2.0 * np.pi * u2)


def beckmann_visible_unit(v: np.ndarray, u1: np.ndarray, u2: np.ndarray) -> np.ndarray:
    """Visible normal of the alpha = 1 Beckmann surface seen from unit v (any direction); seen
    from straight above, in closed form (vertical_slopes)."""
    sin_t = np.hypot(v[..., 0], v[..., 1])
    # cot theta, clipped; the divisor is floored so a denormal sin_t cannot overflow
    mu = np.clip(v[..., 2] / np.maximum(sin_t, 1e-200), -1e4, 1e8)
    mu = np.where(sin_t > 0.0, mu, np.where(v[..., 2] > 0.0, 1e8, -1e4))
    u1 = np.clip(u1, 1e-300, 1.0 - 2.0**-53)
    u2 = np.clip(u2, 2.0**-60, 1.0 - 2.0**-53)
    x = _visible_slope(mu, u1)
    y = ndtri(u2) / np.sqrt(2.0)
    safe = np.where(sin_t > 0.0, sin_t, 1.0)
    c = np.where(sin_t > 0.0, v[..., 0] / safe, 1.0)
    s = np.where(sin_t > 0.0, v[..., 1] / safe, 0.0)
    sx = c * x - s * y
    sy = s * x + c * y
    above = (sin_t == 0.0) & (v[..., 2] > 0.0)
    if np.any(above):
        vx, vy = vertical_slopes(u1, u2)
        sx, sy = np.where(above, vx, sx), np.where(above, vy, sy)
    n = np.stack([-sx, -sy, np.ones_like(sx)], axis=-1)
    return n / np.linalg.norm(n, axis=-1, keepdims=True)
