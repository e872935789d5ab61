"""Microsurface height distributions P1(h) (Heitz et al. 2016): CDF C1, its log, stable inverses.

The random walk lives in the coordinate u = C1(h); these classes map u back to heights, with
log-space forms that stay exact at both tails (u near 0 and near 1).
"""

from __future__ import annotations

import numpy as np
from scipy.special import log_ndtr, ndtr, ndtri_exp

LOG_HALF = float(np.log(0.5))


def log1mexp(x: np.ndarray) -> np.ndarray:
    """log(1 - exp(x)) for x <= 0, accurate for x near 0 and for x very negative (Maechler 2012)."""
    x = np.asarray(x, dtype=np.float64)
    with np.errstate(divide="ignore"):
        return np.where(x > -np.log(2.0), np.log(-np.expm1(x)), np.log1p(-np.exp(x)))


class UniformHeights:
    """Heights uniform on [-1, 1]: P1 = 1/2, C1(h) = (1 + h)/2 (Heitz et al. 2016, section 4)."""

    name = "uniform"

    def pdf(self, h: np.ndarray) -> np.ndarray:
        """Density P1(h)."""
        h = np.asarray(h, dtype=np.float64)
        return np.where(np.abs(h) <= 1.0, 0.5, 0.0)

    def log_cdf(self, h: np.ndarray) -> np.ndarray:
        """log C1(h); -inf below the support, 0 above it."""
        h = np.clip(np.asarray(h, dtype=np.float64), -1.0, 1.0)
        with np.errstate(divide="ignore"):
            return np.log1p(h) + LOG_HALF

    def log_sf(self, h: np.ndarray) -> np.ndarray:
        """log(1 - C1(h)), the CDF of the mirrored surface seen from below."""
        return self.log_cdf(-np.asarray(h, dtype=np.float64))

    def cdf(self, h: np.ndarray) -> np.ndarray:
        """C1(h)."""
        return np.exp(self.log_cdf(h))

    def inv_log_cdf(self, log_u: np.ndarray) -> np.ndarray:
        """Height h with log C1(h) = log_u, from the nearer tail: both ends keep full precision."""
        log_u = np.asarray(log_u, dtype=np.float64)
        low = 2.0 * np.exp(log_u) - 1.0
        high = 1.0 - 2.0 * np.exp(log1mexp(np.minimum(log_u, 0.0)))
        return np.where(log_u < LOG_HALF, low, high)

    def inv_cdf(self, u: np.ndarray) -> np.ndarray:
        """C1^-1(u) = 2u - 1."""
        with np.errstate(divide="ignore"):
            return self.inv_log_cdf(np.log(np.asarray(u, dtype=np.float64)))


class GaussianHeights:
    """Standard normal heights: C1(h) = Phi(h), evaluated through log Phi and its inverse."""

    name = "gaussian"

    def pdf(self, h: np.ndarray) -> np.ndarray:
        """Density P1(h) = exp(-h^2/2)/sqrt(2 pi)."""
        h = np.asarray(h, dtype=np.float64)
        return np.exp(-0.5 * h * h) / np.sqrt(2.0 * np.pi)

    def log_cdf(self, h: np.ndarray) -> np.ndarray:
        """log Phi(h), exact in the far lower tail."""
        return log_ndtr(np.asarray(h, dtype=np.float64))

    def log_sf(self, h: np.ndarray) -> np.ndarray:
        """log(1 - Phi(h)) = log Phi(-h), exact in the far upper tail."""
        return log_ndtr(-np.asarray(h, dtype=np.float64))

    def cdf(self, h: np.ndarray) -> np.ndarray:
        """C1(h) = Phi(h)."""
        return ndtr(np.asarray(h, dtype=np.float64))

    def inv_log_cdf(self, log_u: np.ndarray) -> np.ndarray:
        """Height with log Phi(h) = log_u, from the nearer tail (ndtri_exp of log u or log(1-u))."""
        log_u = np.minimum(np.asarray(log_u, dtype=np.float64), 0.0)
        return np.where(log_u < LOG_HALF, ndtri_exp(log_u), -ndtri_exp(log1mexp(log_u)))

    def inv_cdf(self, u: np.ndarray) -> np.ndarray:
        """Phi^-1(u)."""
        with np.errstate(divide="ignore"):
            return self.inv_log_cdf(np.log(np.asarray(u, dtype=np.float64)))


HEIGHTS = {"uniform": UniformHeights, "gaussian": GaussianHeights}


def make_heights(name: str) -> UniformHeights | GaussianHeights:
    """Height distribution by name ("uniform" or "gaussian"); one clear error for anything else."""
    try:
        return HEIGHTS[name]()
    except (KeyError, TypeError):
        raise ValueError(f"height must be one of {sorted(HEIGHTS)}, got {name!r}") from None
