"""A measured value with its 1-sigma uncertainty, as calibration files store it."""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np

from gonio.errors import GonioError


class Measured(NamedTuple):
    """value +- sigma (1 standard deviation)."""

    value: float
    sigma: float

    def to_json(self) -> dict[str, float]:
        """{"value": v, "sigma": s}."""
        return {"value": float(self.value), "sigma": float(self.sigma)}

    @classmethod
    def from_json(cls, data: Any, where: str) -> Measured:
        """Read {"value", "sigma"}; a CalibrationError names `where` if it is malformed."""
        try:
            value, sigma = float(data["value"]), float(data["sigma"])
        except (TypeError, KeyError, ValueError) as exc:
            raise CalibrationError(f"{where}: must be {{value, sigma}} numbers ({exc})") from exc
        if not (math.isfinite(value) and math.isfinite(sigma) and sigma >= 0):
            raise CalibrationError(f"{where}: value and sigma must be finite, sigma >= 0")
        return cls(value, sigma)

    def pull(self, truth: float) -> float:
        """(value - truth) / sigma: how many sigmas a known truth is away."""
        if self.sigma > 0:
            return (self.value - truth) / self.sigma
        return 0.0 if self.value == truth else math.copysign(math.inf, self.value - truth)


class CalibrationError(GonioError):
    """Calibration data are missing, inconsistent or cannot determine a value."""


def weighted_mean(x: np.ndarray, sigma: np.ndarray | None = None) -> Measured:
    """Mean with its standard error: inverse-variance weighted when sigmas are given, else the
    plain mean with the sample scatter / sqrt(n) (needs n >= 2)."""
    x = np.asarray(x, dtype=np.float64)
    if sigma is None:
        if len(x) < 2:
            raise CalibrationError("need at least two readings to estimate a scatter")
        return Measured(float(x.mean()), float(x.std(ddof=1) / math.sqrt(len(x))))
    w = 1.0 / np.asarray(sigma, dtype=np.float64) ** 2
    return Measured(float(np.sum(w * x) / w.sum()), float(1.0 / math.sqrt(w.sum())))
