"""Incident beam power over a run: linear interpolation between the interleaved straight-through
(beam) readings, so a slow drift of the source divides out of every sample reading.

The uncertainty of an interpolated value combines the readings' own scatter with the
interpolation error, estimated by leave-one-out: each interior beam reading predicted from its
two neighbours; the rms of those misses (less the part their noise explains) is the error of a
value interpolated half-way between readings (a quarter of the two-gap miss), falling to zero
at the readings.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from calibration.values import CalibrationError


@dataclass
class BeamPower:
    """Beam readings (time, corrected power) and their noise; call it at sample times."""

    t_s: np.ndarray
    power_w: np.ndarray
    noise_w: float  # rms noise of one beam reading
    interp_rel: float  # relative interpolation error half-way between readings

    @property
    def mean_w(self) -> float:
        """Mean beam power over the run."""
        return float(self.power_w.mean())

    @property
    def drift_rms(self) -> float:
        """Relative rms variation of the beam readings (drift plus noise)."""
        return float(self.power_w.std() / self.power_w.mean()) if len(self.power_w) > 1 else 0.0

    def at(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(power, 1-sigma) interpolated at times t_s (held constant beyond the ends)."""
        t_s = np.asarray(t_s, dtype=np.float64)
        power = np.interp(t_s, self.t_s, self.power_w)
        if len(self.t_s) < 2:
            return power, np.full(t_s.shape, self.noise_w)
        k = np.clip(np.searchsorted(self.t_s, t_s), 1, len(self.t_s) - 1)
        gap = self.t_s[k] - self.t_s[k - 1]
        u = np.clip((t_s - self.t_s[k - 1]) / np.where(gap > 0, gap, 1.0), 0.0, 1.0)
        # Noise of a linear interpolation of two readings, plus the interpolation error, which
        # vanishes at the readings and peaks half-way (4 u (1 - u)).
        noise = self.noise_w * np.sqrt(u ** 2 + (1.0 - u) ** 2)
        interp = self.interp_rel * power * 4.0 * u * (1.0 - u)
        return power, np.hypot(noise, interp)


def beam_power(t_s: np.ndarray, power_w: np.ndarray, noise_w: float | None = None) -> BeamPower:
    """Beam model from corrected beam readings in time order; `noise_w` is the per-reading noise
    if known (else estimated from second differences, which a slow drift does not affect)."""
    order = np.argsort(t_s)
    t, p = np.asarray(t_s, float)[order], np.asarray(power_w, float)[order]
    if len(p) == 0:
        raise CalibrationError("no beam readings (kind 'beam') to normalise by")
    if np.any(p <= 0):
        raise CalibrationError("a beam reading is <= 0 after dark correction: is the beam "
                               "position right and the source on?")
    if noise_w is None:
        if len(p) >= 3:
            # second difference of white noise has variance 6 sigma^2
            noise_w = float(np.sqrt(np.mean(np.diff(p, 2) ** 2) / 6.0))
        else:
            noise_w = 0.0
    interp_rel = 0.0
    if len(p) >= 3:
        w = (t[1:-1] - t[:-2]) / np.where(t[2:] > t[:-2], t[2:] - t[:-2], 1.0)
        predicted = p[:-2] + w * (p[2:] - p[:-2])
        miss2 = np.mean((p[1:-1] - predicted) ** 2) - 1.5 * noise_w ** 2
        # the miss spans two gaps; a linear interpolation's error grows as the gap squared
        interp_rel = 0.25 * math.sqrt(max(miss2, 0.0)) / float(p.mean())
    return BeamPower(t, p, float(noise_w), interp_rel)
