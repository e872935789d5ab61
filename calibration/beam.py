"""Incident beam power over a run from the interleaved straight-through (beam) readings, so a
slow drift of the source divides out of every sample reading: `smooth_at` (what reduction and
calibration use) takes their mean, or a polynomial in time through all of them when they drift;
`at` interpolates linearly between neighbours.

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
from scipy import stats

from calibration.values import CalibrationError

MAX_DEGREE = 8  # highest polynomial degree tried for a drift over a run


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

    def smooth_at(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Beam power and sigma at times t_s: the mean of all beam readings when they scatter no
        more than their noise (no drift to follow), else a polynomial in time through all of them,
        of the degree with the least leave-one-out error. A smooth drift is so followed with the
        noise of all readings, not of the two nearest, whose errors would be common to every
        sample reading of their gaps (docs/fitting.md, "Beam and drift"); fewer than four beam
        readings: the interpolation of `at`."""
        p, noise = self.power_w, self.noise_w
        if len(p) >= 3 and noise > 0:
            chi2 = float(np.sum((p - p.mean()) ** 2)) / noise**2
            if stats.chi2.sf(chi2, len(p) - 1) > 0.01:
                return (np.full(len(t_s), p.mean()),
                        np.full(len(t_s), noise / math.sqrt(len(p))))
        if len(p) < 4:
            return self.at(t_s)
        span = max(float(self.t_s[-1] - self.t_s[0]), 1e-12)
        x = 2.0 * (self.t_s - self.t_s[0]) / span - 1.0
        x_at = np.clip(2.0 * (np.asarray(t_s, float) - self.t_s[0]) / span - 1.0, -1.0, 1.0)
        best = None
        for degree in range(1, min(len(p) - 3, MAX_DEGREE) + 1):
            design = np.polynomial.legendre.legvander(x, degree)
            inverse = np.linalg.inv(design.T @ design)
            coef = inverse @ design.T @ p
            resid = p - design @ coef
            leverage = np.einsum("ij,jk,ik->i", design, inverse, design)
            loo = float(np.mean((resid / (1.0 - leverage)) ** 2))
            if best is None or loo < best[0]:
                best = (loo, degree, coef, inverse, float(resid @ resid) / (len(p) - degree - 1))
        _, degree, coef, inverse, scatter2 = best
        at = np.polynomial.legendre.legvander(x_at, degree)
        # a reading's noise: the larger of the scatter about the curve and the expected noise
        noise2 = max(scatter2, noise**2)
        return at @ coef, np.sqrt(noise2 * np.einsum("ij,jk,ik->i", at, inverse, at))


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
