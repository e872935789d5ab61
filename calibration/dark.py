"""The run's dark readings as a model: the level, its uncertainty and one reading's noise on each
detector range, used by reduction (calibration.reduce) and the signature (calibration.signature).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from calibration.values import CalibrationError


@dataclass(frozen=True)
class DarkModel:
    """Dark level and per-reading noise per range (W), from the run's dark readings."""

    level: dict[float, float]
    level_sigma: dict[float, float]
    noise: dict[float, float]

    @classmethod
    def from_readings(cls, dark: np.ndarray) -> DarkModel:
        """Mean, its standard error and the scatter of the dark readings on each range."""
        if len(dark) < 2:
            raise CalibrationError("at least two dark readings (kind 'dark') are needed to "
                                   "subtract the dark level and estimate the noise")
        level, level_sigma, noise = {}, {}, {}
        for r in np.unique(dark["range_w"]):
            x = dark["power_w"][dark["range_w"] == r]
            if len(x) >= 2:
                level[float(r)] = float(x.mean())
                noise[float(r)] = float(x.std(ddof=1))
                level_sigma[float(r)] = noise[float(r)] / math.sqrt(len(x))
        if not noise:
            raise CalibrationError("no range has two dark readings: the noise is unknown")
        return cls(level, level_sigma, noise)

    def at(self, range_w: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(dark level, its sigma, one reading's noise) for readings on ranges range_w: a range
        without dark readings takes the nearest range's level and that range's noise scaled
        with the full scale."""
        known = np.array(sorted(self.noise))
        level, level_sigma, noise = (np.empty(len(range_w)) for _ in range(3))
        for i, r in enumerate(range_w):
            if r in self.noise:
                level[i], level_sigma[i], noise[i] = (self.level[r], self.level_sigma[r],
                                                      self.noise[r])
                continue
            near = float(known[np.argmin(np.abs(np.log(known / r)))])
            level[i], level_sigma[i] = self.level[near], self.level_sigma[near]
            noise[i] = self.noise[near] * r / near
        return level, level_sigma, noise
