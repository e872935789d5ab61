"""Smith slope distributions (Beckmann, GGX; anisotropic) for directions on the whole sphere.

The random walk needs Lambda with its sign for downward rays (Lambda(-w) = -1 - Lambda(w)),
the projected area of the microflakes seen from any direction and visible-normal sampling from
directions below the horizon, which the usual single-scattering routines do not cover.
All routines take unit vectors (..., 3) in the local frame (z = macro-normal) and are vectorised.
"""

from __future__ import annotations

import numpy as np
from scipy.special import erfc, erfcx, ndtri

from sim.bsdf.distributions import Distribution, make_distribution

SQRT_PI = float(np.sqrt(np.pi))


class SlopeDistribution:
    """A Beckmann or GGX distribution of sim.bsdf.distributions, extended to the whole sphere."""

    def __init__(self, distribution: Distribution):
        if distribution.name not in ("beckmann", "ggx"):
            raise ValueError(
                "multiple scattering needs a Smith slope distribution 'beckmann' or 'ggx', "
                f"got {distribution.name!r}"
            )
        if np.ndim(distribution.alpha_x) or np.ndim(distribution.alpha_y):
            raise ValueError("multiple scattering needs one scalar alpha (or alpha_x, alpha_y)")
        self.distribution = distribution
        self.name = distribution.name
        self.alpha_x = float(distribution.alpha_x)
        self.alpha_y = float(distribution.alpha_y)

    @classmethod
    def named(cls, name: str, alpha: float | tuple[float, float]) -> SlopeDistribution:
        """Build from a distribution name and alpha (float or (alpha_x, alpha_y))."""
        return cls(make_distribution(name, alpha))

    def z_lambda(self, w: np.ndarray) -> np.ndarray:
        """|w_z| Lambda(w_up) for the upward twin of w; finite at grazing angles."""
        return self.distribution.cos_lambda(w)

    def lambda_(self, w: np.ndarray) -> np.ndarray:
        """Smith Lambda(w) with its sign: >= 0 upward, <= -1 downward; +inf exactly horizontal."""
        z = w[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            up = self.z_lambda(w) / np.abs(z)
        up = np.where(np.abs(z) > 0.0, up, np.inf)
        return np.where(z >= 0.0, up, -1.0 - up)

    def projected_area(self, w: np.ndarray) -> np.ndarray:
        """Integral of <w, m>+ D(m) dm = w_z (1 + Lambda(w)), for w anywhere on the sphere."""
        return np.maximum(w[..., 2], 0.0) + self.z_lambda(w)

    def D(self, m: np.ndarray) -> np.ndarray:
        """Normal distribution D(m) in 1/sr (zero for m_z <= 0)."""
        return self.distribution.D(m)

    def D_visible(self, w: np.ndarray, m: np.ndarray) -> np.ndarray:
        """Normals visible from w (any direction): <w,m>+ D(m) / projected_area(w)."""
        cos = np.maximum(np.sum(w * m, axis=-1), 0.0)
        area = self.projected_area(w)
        with np.errstate(divide="ignore", invalid="ignore"):
            out = cos * self.D(m) / area
        return np.where(area > 0.0, out, 0.0)

    def sample_visible(self, w: np.ndarray, u1: np.ndarray, u2: np.ndarray) -> np.ndarray:
        """A normal m ~ D_visible(w, .) for w on the whole sphere, by stretching to alpha = 1."""
        ax, ay = self.alpha_x, self.alpha_y
        v = np.stack([ax * w[..., 0], ay * w[..., 1], w[..., 2]], axis=-1)
        v /= np.linalg.norm(v, axis=-1, keepdims=True)
        if self.name == "ggx":
            n = _ggx_visible_unit(v, u1, u2)
        else:
            n = _beckmann_visible_unit(v, u1, u2)
        m = np.stack([ax * n[..., 0], ay * n[..., 1], np.maximum(n[..., 2], 0.0)], axis=-1)
        return m / np.linalg.norm(m, axis=-1, keepdims=True)


def _tangent_frame(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """T1 horizontal and perpendicular to v, T2 = v x T1 (so T2_z = sin theta_v >= 0)."""
    lensq = v[..., 0] ** 2 + v[..., 1] ** 2
    inv = np.where(lensq > 0.0, 1.0 / np.sqrt(np.where(lensq > 0.0, lensq, 1.0)), 0.0)
    t1 = np.stack([-v[..., 1] * inv, v[..., 0] * inv, np.zeros_like(inv)], axis=-1)
    t1[lensq == 0.0] = (1.0, 0.0, 0.0)
    return t1, np.cross(v, t1)


def _ggx_visible_unit(v: np.ndarray, u1: np.ndarray, u2: np.ndarray) -> np.ndarray:
    """Visible normals of the unit upper hemisphere seen from v, for v above or below the horizon.

    The visible part projects, in the plane normal to v, onto the disk region
    t2 in [-v_z sqrt(1 - t1^2), sqrt(1 - t1^2)] (Heitz 2018 for v_z > 0; the same region
    bound holds for v_z < 0), sampled uniformly by a linear warp of a uniform disk point.
    """
    t1v, t2v = _tangent_frame(v)
    r = np.sqrt(u1)
    phi = 2.0 * np.pi * u2
    t1 = r * np.cos(phi)
    t2 = r * np.sin(phi)
    s = 0.5 * (1.0 + v[..., 2])
    h = np.sqrt(np.maximum(0.0, 1.0 - t1 * t1))
    t2 = (1.0 - s) * h + s * t2
    n = (
        t1[..., None] * t1v
        + t2[..., None] * t2v
        + np.sqrt(np.maximum(0.0, 1.0 - t1 * t1 - t2 * t2))[..., None] * v
    )
    return n


def _beckmann_log_cdf(x: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """log F(x), F(x) = int_{-inf}^x (mu - t) exp(-t^2)/sqrt(pi) dt (x <= mu); stable tails."""
    neg = x <= 0.0
    xn = np.where(neg, x, 0.0)
    xp = np.where(neg, 0.0, x)
    with np.errstate(divide="ignore", invalid="ignore"):
        left = -xn * xn + np.log(mu * erfcx(-xn) + 1.0 / SQRT_PI)
        right = np.log(mu * erfc(-xp) + np.exp(-xp * xp) / SQRT_PI)
    return np.where(neg, left, right) - np.log(2.0)


def _beckmann_visible_slope(mu: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Slope x < mu with density proportional to (mu - x) exp(-x^2), by inversion of its CDF.

    log F is concave (the density is log-concave), so Newton's method started left of the root
    climbs to it monotonically; the start comes from F(x) <= exp(-x^2)(max(mu,0) + 1/sqrt(pi))/2.
    """
    target = np.log(u) + _beckmann_log_cdf(mu, mu)
    bound = np.log(0.5 * (np.maximum(mu, 0.0) + 1.0 / SQRT_PI)) - target
    x = np.minimum(-np.sqrt(np.maximum(bound, 0.0)), mu)
    for _ in range(60):
        g = _beckmann_log_cdf(x, mu)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            log_f = np.log(np.maximum(mu - x, 0.0)) - x * x - np.log(SQRT_PI)
            step = (target - g) / np.exp(log_f - g)
        step = np.where(np.isfinite(step) & (step > 0.0), step, 0.0)
        x = np.minimum(x + step, mu)
        if np.all(step <= 1e-13 * (1.0 + np.abs(x))):
            break
    return x


def _beckmann_visible_unit(v: np.ndarray, u1: np.ndarray, u2: np.ndarray) -> np.ndarray:
    """Visible normal of the alpha = 1 Beckmann surface seen from unit v (any direction)."""
    sin_t = np.hypot(v[..., 0], v[..., 1])
    # cot theta, clipped; the divisor is floored so a denormal sin_t cannot overflow
    mu = np.clip(v[..., 2] / np.maximum(sin_t, 1e-200), -1e4, 1e8)
    mu = np.where(sin_t > 0.0, mu, np.where(v[..., 2] > 0.0, 1e8, -1e4))
    u1 = np.clip(u1, 1e-300, 1.0 - 2.0**-53)
    u2 = np.clip(u2, 2.0**-60, 1.0 - 2.0**-53)
    x = _beckmann_visible_slope(mu, u1)
    y = ndtri(u2) / np.sqrt(2.0)
    safe = np.where(sin_t > 0.0, sin_t, 1.0)
    c = np.where(sin_t > 0.0, v[..., 0] / safe, 1.0)
    s = np.where(sin_t > 0.0, v[..., 1] / safe, 0.0)
    sx = c * x - s * y
    sy = s * x + c * y
    n = np.stack([-sx, -sy, np.ones_like(sx)], axis=-1)
    return n / np.linalg.norm(n, axis=-1, keepdims=True)
