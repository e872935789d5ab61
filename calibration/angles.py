"""Angle zero offsets from the symmetry of measured peaks.

Convention (as sim.bench's scene): true angle = reported angle + offset. The straight-through
beam peaks at true arm 180, so its reported centre c_b gives arm_offset = 180 - c_b. The
specular peak of a sample at reported angle s sits at true arm 2 (s + sample_offset), so its
reported centre c_s gives sample_offset = (c_s + arm_offset) / 2 - s. A peak's centre is where
the curve is best mirror-symmetric: the power at x and at 2c - x agree (linear interpolation of
the measured curve), found by least squares; its uncertainty from a seeded parametric bootstrap
over the readings' noise.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import minimize_scalar

from calibration.values import CalibrationError, Measured


def _asymmetry(centre: float, x: np.ndarray, p: np.ndarray, core: np.ndarray) -> float:
    mirrored = np.interp(2.0 * centre - x[core], x, p, left=np.nan, right=np.nan)
    diff = p[core] - mirrored
    diff = diff[np.isfinite(diff)]
    return float(np.mean(diff ** 2)) if len(diff) >= 3 else np.inf


def symmetry_centre(x: np.ndarray, power: np.ndarray, core_fraction: float = 0.05) -> float:
    """Centre of a single peak from mirror symmetry of its core (p > fraction of the maximum),
    searched where the peak is above half its maximum."""
    order = np.argsort(x)
    x, p = np.asarray(x, float)[order], np.asarray(power, float)[order]
    k = int(np.argmax(p))
    core = p > core_fraction * p[k]
    top = x[p > 0.5 * p[k]]
    lo, hi = top.min(), top.max()
    if core.sum() < 3 or hi <= lo:
        raise CalibrationError("the peak is sampled by fewer than three points above "
                               f"{core_fraction:.0%} of its maximum; scan it more finely")
    best = minimize_scalar(_asymmetry, bounds=(lo, hi), args=(x, p, core), method="bounded",
                           options={"xatol": 1e-6 * (hi - lo)})
    return float(best.x)


def peak_centre(x: np.ndarray, power: np.ndarray, sigma: np.ndarray, n_boot: int = 64,
                seed: int = 0) -> Measured:
    """Symmetry centre with its 1-sigma uncertainty from resampling the readings' noise."""
    centre = symmetry_centre(x, power)
    rng = np.random.default_rng(seed)
    boots = [symmetry_centre(x, power + sigma * rng.standard_normal(len(power)))
             for _ in range(n_boot)]
    return Measured(centre, float(np.std(boots, ddof=1)))


def arm_offset(beam_centre: Measured) -> Measured:
    """Arm zero offset from the reported centre of the straight-through peak."""
    return Measured(180.0 - beam_centre.value, beam_centre.sigma)


def sample_offset(specular_centre: Measured, sample_deg: float, arm: Measured) -> Measured:
    """Sample zero offset from the reported centre of the specular peak at reported sample
    angle `sample_deg`, given the arm offset."""
    value = 0.5 * (specular_centre.value + arm.value) - sample_deg
    return Measured(value, 0.5 * float(np.hypot(specular_centre.sigma, arm.sigma)))
