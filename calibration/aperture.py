"""Detector aperture solid angle: from its geometry, or measured by scanning across the beam.

Scanning the arm across a collimated beam of angular radius b (radius / distance) with a
circular aperture of angular radius a, the collected fraction of the beam at offset u is the
overlap of two disks. Its integral over u, divided by the fully-collected power, is the beam's
average of the aperture's chord 2 sqrt(a^2 - y^2) (y the beam point's distance from the scan
line), which is 2a for a beam much smaller than the aperture. The equivalent width W of the
scan (area / plateau) therefore fixes a, and Omega = 2 pi (1 - cos atan a).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import brentq

from calibration.values import CalibrationError, Measured


def solid_angle_sr(half_angle_rad: float) -> float:
    """Solid angle of a circular aperture seen under half-angle beta: 2 pi (1 - cos beta)."""
    return 4.0 * math.pi * math.sin(0.5 * half_angle_rad) ** 2


def from_geometry(radius_m: float, distance_m: float) -> float:
    """Solid angle (sr) of a circular aperture of given radius at a distance from the sample."""
    if radius_m <= 0 or distance_m <= 0:
        raise CalibrationError(f"aperture radius and distance must be > 0, got {radius_m!r}, "
                               f"{distance_m!r}")
    return solid_angle_sr(math.atan2(radius_m, distance_m))


def _mean_chord(a: float, b: float) -> float:
    """Average over a uniform disk of radius b of 2 sqrt(a^2 - y^2) (0 beyond |y| = a)."""
    if b == 0.0:
        return 2.0 * a
    y, w = np.polynomial.legendre.leggauss(64)
    y = b * 0.5 * (y + 1.0)  # y in [0, b], the density is even in y
    density = (4.0 / (math.pi * b * b)) * np.sqrt(b * b - y * y) * 0.5 * b
    return float(np.sum(w * density * 2.0 * np.sqrt(np.clip(a * a - y * y, 0.0, None))))


def from_beam_scan(arm_deg: np.ndarray, power_w: np.ndarray, sigma_w: np.ndarray,
                   beam_radius_rad: float = 0.0) -> tuple[Measured, Measured]:
    """(solid angle sr, half-angle deg) of the aperture from an arm scan across the straight
    beam, which must cover the whole beam profile and reach its plateau (aperture larger than
    the beam). The plateau is the mean of the readings within 2 % of the largest."""
    order = np.argsort(arm_deg)
    x = np.radians(np.asarray(arm_deg, float)[order])
    p, s = np.asarray(power_w, float)[order], np.asarray(sigma_w, float)[order]
    top = p > 0.98 * p.max()
    if top.sum() < 2 or p[0] > 0.02 * p.max() or p[-1] > 0.02 * p.max():
        raise CalibrationError("the beam scan must reach a plateau (two readings or more) and "
                               "fall below 2 % of it at both ends")
    plateau = float(np.mean(p[top]))
    plateau_sigma = float(np.std(p[top], ddof=1) / math.sqrt(top.sum()))
    dx = np.gradient(x)
    area = float(np.trapezoid(p, x))
    area_sigma = float(math.sqrt(np.sum((dx * s) ** 2)))
    width = area / plateau
    width_sigma = width * math.hypot(area_sigma / area, plateau_sigma / plateau)

    def half_angle(w: float) -> float:
        if beam_radius_rad == 0.0:
            return 0.5 * w
        return brentq(lambda a: _mean_chord(a, beam_radius_rad) - w, 1e-9, 10.0 * w + 1.0)

    a = half_angle(width)
    da = abs(half_angle(width + width_sigma) - a)
    beta, dbeta = math.atan(a), da / (1.0 + a * a)
    omega = solid_angle_sr(beta)
    return (Measured(omega, omega * 2.0 * dbeta / beta),
            Measured(math.degrees(beta), math.degrees(dbeta)))
