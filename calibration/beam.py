"""Incident beam power over a run from the interleaved straight-through (beam) readings, so a
slow drift of the source divides out of every sample reading: `smooth` (what reduction and
calibration use) fits one polynomial in time, at least a straight line, through all beam
readings; `at` interpolates linearly between neighbours.

Both are linear in the beam readings, so besides each value's sigma they give the errors the
values share: a beam reading's noise moves the curve at every time at once, a common-mode error
of all sample readings that a fit must see as such (ReducedData.shared_rel), not as independent
noise. The uncertainty of `at` adds the interpolation error, estimated by leave-one-out: each
interior beam reading predicted from its two neighbours; the rms of those misses (less the part
their noise explains) is the error of a value interpolated half-way between readings (a quarter
of the two-gap miss), falling to zero at the readings.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from calibration.values import CalibrationError

MAX_DEGREE = 8  # highest polynomial degree tried for a drift over a run
# Each degree above 1 must lower the beam readings' chi-square by this much (3 sigma for one
# parameter). Least leave-one-out error picked degrees 2-8 in a third of runs whose drift was a
# straight line to 1e-4, fitting the noise, and their errors came out 1.2-1.4 times the sigma.
DEGREE_PENALTY = 9.0


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
        power, sigma, _ = self.interpolate(t_s)
        return power, sigma

    def interpolate(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Linear interpolation between neighbouring readings: (power, sigma, shared), shared
        (len(t_s), readings) the error each reading's noise puts into the values (their shared
        part; sigma adds the interpolation error, which vanishes at the readings and peaks
        half-way, 4 u (1 - u))."""
        t_s = np.asarray(t_s, dtype=np.float64)
        weights = np.zeros((len(t_s), len(self.t_s)))
        if len(self.t_s) < 2:
            weights[:, 0] = 1.0
            return np.full(t_s.shape, self.power_w[0]), np.full(t_s.shape, self.noise_w), \
                self.noise_w * weights
        k = np.clip(np.searchsorted(self.t_s, t_s), 1, len(self.t_s) - 1)
        gap = self.t_s[k] - self.t_s[k - 1]
        u = np.clip((t_s - self.t_s[k - 1]) / np.where(gap > 0, gap, 1.0), 0.0, 1.0)
        rows = np.arange(len(t_s))
        weights[rows, k - 1], weights[rows, k] = 1.0 - u, u
        power = weights @ self.power_w
        shared = self.noise_w * weights
        interp = self.interp_rel * power * 4.0 * u * (1.0 - u)
        return power, np.hypot(np.linalg.norm(shared, axis=1), interp), shared

    def smooth_at(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Beam power and its 1-sigma at times t_s (see `smooth`)."""
        power, sigma, _ = self.smooth(t_s)
        return power, sigma

    def smooth(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Beam power at times t_s from one polynomial in time through all beam readings, of
        degree 1 to MAX_DEGREE by the least chi-square plus DEGREE_PENALTY per degree, with the
        readings' noise taken as the larger of its expected value and the scatter about the
        highest degree: (power, sigma, shared), shared
        (len(t_s), degree + 1) with the values' errors shared @ z, z ~ N(0, I).

        Never a constant: a drift below what the readings can detect (a 1 % source drifting
        over a short run) still biases the mean by up to half its change at the run's ends,
        while the mean's sigma claims the readings' noise over sqrt(n); a straight line follows
        it for at most twice that sigma. All readings, not the two nearest, carry the curve, so
        no one reading's noise dominates a gap (docs/fitting.md, "Beam and drift"). Fewer than
        four readings: the interpolation of `interpolate`."""
        p = self.power_w
        if len(p) < 4:
            return self.interpolate(t_s)
        span = max(float(self.t_s[-1] - self.t_s[0]), 1e-12)
        x = 2.0 * (self.t_s - self.t_s[0]) / span - 1.0
        x_at = np.clip(2.0 * (np.asarray(t_s, float) - self.t_s[0]) / span - 1.0, -1.0, 1.0)
        fits = []
        for degree in range(1, min(len(p) - 3, MAX_DEGREE) + 1):
            design = np.polynomial.legendre.legvander(x, degree)
            inverse = np.linalg.inv(design.T @ design)
            coef = inverse @ design.T @ p
            resid = p - design @ coef
            fits.append((degree, coef, inverse, float(resid @ resid)))
        # a reading's noise: the larger of the expected noise and the scatter about the curve
        # of highest degree (which holds any drift the readings can show)
        noise2 = max(self.noise_w**2, fits[-1][3] / (len(p) - fits[-1][0] - 1))
        degree, coef, inverse, _ = min(fits, key=lambda f: f[3] / noise2 + DEGREE_PENALTY * f[0])
        at = np.polynomial.legendre.legvander(x_at, degree)
        shared = math.sqrt(noise2) * at @ np.linalg.cholesky(inverse)
        return at @ coef, np.linalg.norm(shared, axis=1), shared


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
