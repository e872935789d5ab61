"""Angle zero offsets from scans across the transmitted and specular peaks of a smooth sample.

Convention (as sim.bench's scene): true angle = reported angle + offset. The offsets are fitted
with the microfacet model of the reference sample: every scan's readings against
scale_k * <f |cos o|>(reported + offsets), the model averaged over the aperture and the beam's
divergence (calibration.smearing), with the sample offset, arm offset, alpha and one scale per
scan free, by weighted least squares; the distribution (Beckmann or GGX) is the one that fits
better on a coarse alpha grid at the start. A peak's mirror-symmetry centre is only the
starting point: a real lobe is not symmetric about its geometric direction (Fresnel and masking
vary across a reflected lobe), and linear interpolation of a coarsely sampled peak biases a
symmetry centre too; together 1-3e-4 deg on an anti-glare reference, several sigma.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares, minimize_scalar

from calibration.smearing import Smearing, smearing_order
from calibration.values import CalibrationError, Measured

DISTRIBUTIONS = ("beckmann", "ggx")
ALPHA_BOUNDS = (1e-3, 1.0)  # reference samples for angle calibration are smooth
# Alpha's starting grid folds the aperture and the divergence into one cap of half-angle
# hypot(aperture, divergence) (their second moments add) on a cheap order-3 rule; the fit
# itself averages over both caps at the orders calibration.fit uses (with the folded cap the
# anti-glare peaks fit at chi2/dof 10, with both caps at 0.6).
GRID_CAP_ORDER = 3
# Absolute central-difference steps of the fit's Jacobian: degrees for the two offsets, ln alpha
# for alpha. scipy's diff_step is relative to each parameter, so it gives an offset near zero (a
# bench aligned well) a step below the float spacing of the stage angles it is added to: a zero
# Jacobian column, or one quantised to a few ulps, and with it a wrong covariance. 1e-5 deg is
# 2e-5 of the narrowest peak's width (0.45 deg; truncation error ~1e-10) and 3e8 ulps of 180 deg.
JACOBIAN_STEPS = np.array([1e-5, 1e-5, 1e-5, 1e-5])  # the last: the aperture's half-angle, deg


@dataclass
class PeakScan:
    """One scan across a peak: stage positions of its points, the mean (beam-normalised) power
    of each point's repeats and its standard error."""

    side: str  # "reflection" | "transmission"
    sample_deg: np.ndarray
    arm_deg: np.ndarray
    elevation_deg: np.ndarray
    azimuth_deg: np.ndarray
    power_w: np.ndarray
    sigma_w: np.ndarray


@dataclass
class OffsetFit:
    """Fitted zero offsets and what the fit found about the reference sample."""

    sample_offset: Measured
    arm_offset: Measured
    distribution: str
    alpha: Measured
    chi2_dof: float
    n_points: int
    aperture_half_angle: Measured | None = None  # fitted within its prior (fit_offsets)


def _asymmetry(centre: float, x: np.ndarray, p: np.ndarray, core: np.ndarray) -> float:
    mirrored = np.interp(2.0 * centre - x[core], x, p, left=np.nan, right=np.nan)
    diff = p[core] - mirrored
    diff = diff[np.isfinite(diff)]
    return float(np.mean(diff ** 2)) if len(diff) >= 3 else np.inf


def symmetry_centre(x: np.ndarray, power: np.ndarray, core_fraction: float = 0.05) -> float:
    """Centre of a single peak from mirror symmetry of its core (p > fraction of the maximum),
    searched where the peak is above half its maximum (a starting value: see the module)."""
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


def symmetric_estimate(scans: list[PeakScan], eta: float) -> tuple[float, float]:
    """(sample, arm) offsets from the peaks' symmetry centres: the transmitted peak at reported
    sample s sits at reported arm 180 + (s + ds)(1 - 1/eta) - da (small incidence), a specular
    peak at 2 (s + ds) - da. Least squares over the scans; needs one of each kind."""
    k_t = 1.0 - 1.0 / eta
    rows, rhs = [], []
    for scan in scans:
        s = float(np.mean(scan.sample_deg))
        c = symmetry_centre(scan.arm_deg, scan.power_w)
        if scan.side == "transmission":
            rows.append([k_t, -1.0])
            rhs.append(c - 180.0 - k_t * s)
        else:
            rows.append([2.0, -1.0])
            rhs.append(c - 2.0 * s)
    if len({scan.side for scan in scans}) < 2:
        raise CalibrationError("angle calibration needs a transmission scan at normal incidence "
                               "and a reflection scan across the specular peak")
    coef, *_ = np.linalg.lstsq(np.array(rows), np.array(rhs), rcond=None)
    return float(coef[0]), float(coef[1])


class _PeakModel:
    """Scale-free model power <f |cos o|> of each scan at offsets (ds, da) for one sample."""

    def __init__(self, scans: list[PeakScan], distribution: str, eta: float,
                 aperture_deg: float, divergence_deg: float):
        self.scans, self.distribution, self.eta = scans, distribution, eta
        self.aperture_deg, self.divergence_deg = aperture_deg, divergence_deg
        cap_deg = math.hypot(aperture_deg, divergence_deg)
        self.optics = Smearing(cap_deg, GRID_CAP_ORDER if cap_deg > 0 else 0, 0.0, 0)

    def resolve(self, alpha: float) -> None:
        """Average over the aperture and the divergence cone at orders resolving alpha."""
        self.orders = (smearing_order(self.aperture_deg, alpha),
                       smearing_order(self.divergence_deg, alpha))
        self.optics = Smearing(self.aperture_deg, self.orders[0], self.divergence_deg,
                               self.orders[1])

    def widen(self, aperture_deg: float) -> None:
        """The aperture's half-angle set to aperture_deg, at the orders `resolve` chose (so
        that the model is smooth in it)."""
        if aperture_deg != self.aperture_deg:
            self.aperture_deg = aperture_deg
            self.optics = Smearing(aperture_deg, self.orders[0], self.divergence_deg,
                                   self.orders[1])

    def shapes(self, ds: float, da: float, alpha: float) -> list[np.ndarray]:
        """Per scan, the model's <f |cos o|> at its reported stage angles plus the offsets."""
        from calibration.fit import build_model
        from gonio.geometry import directions

        model = build_model(self.distribution, alpha, self.eta, "separable")
        out = []
        for scan in self.scans:
            wi, wo = directions(scan.sample_deg + ds, scan.arm_deg + da, scan.elevation_deg,
                                scan.azimuth_deg)
            out.append(self.optics.average(model, wi, wo) * np.abs(wo[:, 2]))
        return out


def _best_scales(shapes: list[np.ndarray], scans: list[PeakScan]) -> list[float]:
    """Per scan, the scale minimising chi-square for fixed shapes (linear least squares)."""
    out = []
    for shape, scan in zip(shapes, scans, strict=True):
        w = 1.0 / scan.sigma_w ** 2
        out.append(float(np.sum(w * shape * scan.power_w) / max(np.sum(w * shape ** 2), 1e-300)))
    return out


def _residuals(shapes: list[np.ndarray], scales: list[float], scans: list[PeakScan]
               ) -> np.ndarray:
    return np.concatenate([(c * shape - scan.power_w) / scan.sigma_w
                           for shape, c, scan in zip(shapes, scales, scans, strict=True)])


def _start(scans: list[PeakScan], eta: float, aperture_deg: float, divergence_deg: float,
           offsets: tuple[float, float]) -> tuple[_PeakModel, float]:
    """The distribution and alpha that fit best on a coarse grid (cheap folded cap), at the
    symmetry estimate of the offsets."""
    best = None
    for distribution in DISTRIBUTIONS:
        model = _PeakModel(scans, distribution, eta, aperture_deg, divergence_deg)
        for alpha in np.geomspace(*ALPHA_BOUNDS, 10):
            shapes = model.shapes(*offsets, alpha)
            scales = _best_scales(shapes, scans)
            chi2 = float(np.sum(_residuals(shapes, scales, scans) ** 2))
            if min(scales) > 0 and (best is None or chi2 < best[0]):
                best = (chi2, model, float(alpha))
    if best is None:
        raise CalibrationError("a peak scan holds no peak of the reference sample (no "
                               "positive scale fits it)")
    return best[1], best[2]


def _central_jacobian(residuals: Callable[[np.ndarray], np.ndarray], x: np.ndarray
                      ) -> np.ndarray:
    """d residuals / dx by central differences with the absolute JACOBIAN_STEPS."""
    columns = []
    for k, h in enumerate(JACOBIAN_STEPS[:len(x)]):
        step = np.zeros_like(x)
        step[k] = h
        columns.append((residuals(x + step) - residuals(x - step)) / (2.0 * h))
    return np.column_stack(columns)


def fit_offsets(scans: list[PeakScan], eta: float, aperture_half_angle_deg: float = 0.0,
                divergence_deg: float = 0.0, aperture_sigma_deg: float = 0.0) -> OffsetFit:
    """Sample and arm zero offsets (degrees) from peak scans of a smooth reference sample of
    index eta, by the model fit of the module docstring (the scans' scales solved linearly
    inside: variable projection, so the Jacobian gives the offsets' covariance with the scales
    marginalised); sigmas scaled by chi-square per degree of freedom when that exceeds 1.
    With aperture_sigma_deg > 0 the aperture's half-angle is fitted too, within that prior
    about aperture_half_angle_deg (a residual (beta - beta0) / sigma): a peak as narrow as an
    anti-glare reference's is so sensitive to the aperture's width that its measured or
    nominal value's own error (a beam scan's 3e-4 deg) would bias the offsets and the fit."""
    start = symmetric_estimate(scans, eta)
    n = sum(len(scan.power_w) for scan in scans)
    dof = n - 3 - len(scans)  # offsets, alpha and a scale per scan
    if dof < 1:
        raise CalibrationError(f"{n} averaged points cannot fit two offsets, alpha and "
                               f"{len(scans)} scales")
    model, alpha0 = _start(scans, eta, aperture_half_angle_deg, divergence_deg, start)
    model.resolve(alpha0)
    free_aperture = aperture_sigma_deg > 0 and aperture_half_angle_deg > 0

    def residuals(x: np.ndarray) -> np.ndarray:
        prior = []
        if free_aperture:
            model.widen(x[3])
            prior = [(x[3] - aperture_half_angle_deg) / aperture_sigma_deg]
        shapes = model.shapes(x[0], x[1], math.exp(x[2]))
        return np.append(_residuals(shapes, _best_scales(shapes, scans), scans), prior)

    x0 = [*start, math.log(alpha0)]
    low, high = [-np.inf, -np.inf, math.log(ALPHA_BOUNDS[0])], [np.inf, np.inf,
                                                                  math.log(ALPHA_BOUNDS[1])]
    if free_aperture:  # within 10 sigma of its prior, and open
        x0.append(aperture_half_angle_deg)
        low.append(max(aperture_half_angle_deg - 10.0 * aperture_sigma_deg,
                       1e-3 * aperture_half_angle_deg))
        high.append(aperture_half_angle_deg + 10.0 * aperture_sigma_deg)
    sol = least_squares(residuals, np.array(x0), bounds=(low, high),
                        jac=lambda x: _central_jacobian(residuals, x), x_scale="jac",
                        xtol=1e-10, ftol=1e-10)
    jtj = sol.jac.T @ sol.jac
    if np.linalg.matrix_rank(jtj) < len(x0):
        raise CalibrationError("the peak scans do not determine both offsets (is every peak "
                               "inside its scan?)")
    chi2 = float(np.sum(sol.fun ** 2))
    cov = np.linalg.inv(jtj) * max(1.0, chi2 / dof)
    alpha = math.exp(sol.x[2])
    aperture = (Measured(float(sol.x[3]), math.sqrt(cov[3, 3])) if free_aperture else None)
    return OffsetFit(Measured(float(sol.x[0]), math.sqrt(cov[0, 0])),
                     Measured(float(sol.x[1]), math.sqrt(cov[1, 1])), model.distribution,
                     Measured(alpha, alpha * math.sqrt(cov[2, 2])), chi2 / dof, n, aperture)
