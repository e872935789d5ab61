"""Directional albedo (reflectance R and transmittance T) of a fit's model and of the
single-scattering material Mitsuba renders for it, and the tables that make up the difference:
what the `gonio_multiscatter` plugin (calibration.exports.mitsuba_plugin) adds, and what a
single-scattering export drops.

R and T of a single-scattering model come from its own sample() over a scrambled Sobol set;
those of orders >= 2 from the random walk of the fit's microsurface (the term the fit added,
calibration.fit.model), counted by the side each walk leaves on.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from calibration.fit import FitResult
from calibration.fit.model import build_model

#: Incidence angles (deg from the lit side's normal) of the plugin's tables: closer towards
#: grazing, where the albedos change fastest.
THETA_NODES_DEG = (*range(0, 60, 5), *np.arange(60.0, 80.0, 2.5), *range(80, 90))
#: Incidence angles at which the comparisons of the docs and of the CLI's line are made.
REPORT_ANGLES_DEG = (0.0, 30.0, 60.0, 85.0)
#: Largest relative difference of the material's R + T from the model's (at the nodes and
#: between them) that the export accepts.
MAX_ALBEDO_ERROR = 0.01
SOBOL_POINTS = 1 << 13
WALKS = 1 << 15
SEED = 20240613


@dataclass(frozen=True)
class Albedo:
    """R and T at angles, for light arriving from outside (+z) and from inside."""

    theta_deg: np.ndarray
    outside: tuple[np.ndarray, np.ndarray]
    inside: tuple[np.ndarray, np.ndarray]

    def total(self) -> np.ndarray:
        """R + T from outside."""
        return self.outside[0] + self.outside[1]


def incidence(theta_deg: float, outside: bool) -> np.ndarray:
    """Unit direction toward the light at theta_deg from the normal of its side (x-z plane)."""
    t = math.radians(theta_deg)
    return np.array([math.sin(t), 0.0, math.cos(t) if outside else -math.cos(t)])


def _split(wo: np.ndarray, weight: np.ndarray, outside: bool, n: int) -> tuple[float, float]:
    """(R, T): the weights summed by the side wo leaves on, over n samples."""
    same = (wo[:, 2] > 0.0) == outside
    return (float(np.sum(np.where(same, weight, 0.0)) / n),
            float(np.sum(np.where(same | (wo[:, 2] == 0.0), 0.0, weight)) / n))


@functools.cache
def _sobol() -> np.ndarray:
    """SOBOL_POINTS scrambled Sobol points in [0, 1)^3 (the same for every call)."""
    from scipy.stats import qmc

    return qmc.Sobol(3, seed=SEED).random(SOBOL_POINTS)


def single_albedo(model, theta_deg: float, outside: bool) -> tuple[float, float]:
    """(R, T) of a single-scattering model.bsdf model, by its own sample()."""
    wo, weight, _ = model.sample(incidence(theta_deg, outside), _sobol())
    return _split(wo, np.nan_to_num(weight), outside, SOBOL_POINTS)


def higher_orders_albedo(result: FitResult, theta_deg: float, outside: bool
                         ) -> tuple[float, float]:
    """(R, T) of the random walk's orders >= 2 on the fit's microsurface: split by WALKS walks;
    for a dielectric their sum is energy_loss (the walk conserves energy, so orders >= 2 carry
    exactly what order 1 loses: deterministic, no Monte Carlo error in R + T)."""
    from model.bsdf.multiple_scattering import RandomWalkBSDF, energy_loss

    surface = build_model(result.distribution, result.alpha, result.eta, "correlated", result.k)
    walker = RandomWalkBSDF(surface, walks=1).walker
    wi = np.repeat(incidence(theta_deg, outside)[None], WALKS, axis=0)
    walked = walker.run(wi, np.random.default_rng(SEED))
    weight = np.where(walked.orders >= 2, np.nan_to_num(walked.weight), 0.0)
    r, t = _split(np.nan_to_num(walked.exit_direction), weight, outside, WALKS)
    if result.k is not None or r + t == 0.0:
        return r, t
    eta = result.eta if outside else 1.0 / result.eta
    total = energy_loss(result.distribution, result.alpha, eta, math.radians(theta_deg))
    return total * r / (r + t), total * t / (r + t)


def _albedo(parts, theta_deg) -> Albedo:
    """Albedo of the sum of `parts` (callables (theta, outside) -> (R, T)) at theta_deg."""
    sides = []
    for outside in (True, False):
        rt = np.array([np.sum([p(t, outside) for p in parts], axis=0) for t in theta_deg])
        sides.append((rt[:, 0], rt[:, 1]))
    return Albedo(np.asarray(theta_deg, dtype=float), sides[0], sides[1])


def model_albedo(result: FitResult, theta_deg) -> Albedo:
    """Albedo of the fitted model (scale included): its single scattering plus, when the fit
    used it, orders >= 2."""
    single = build_model(result.distribution, result.alpha, result.eta, result.masking, result.k)
    parts = [lambda t, o: single_albedo(single, t, o)]
    if result.walks is not None:
        parts.append(lambda t, o: higher_orders_albedo(result, t, o))
    return _scaled(_albedo(parts, theta_deg), result.scale)


def material_albedo(result: FitResult, theta_deg) -> Albedo:
    """Albedo of the single-scattering material Mitsuba renders (scale included): the fit's
    alpha and index with separable masking, Beckmann for Phong (gonio's separable model is
    Mitsuba's roughdielectric / roughconductor, tests/fitting/test_exports_mitsuba.py)."""
    distribution = "beckmann" if result.distribution == "phong" else result.distribution
    single = build_model(distribution, result.alpha, result.eta, "separable", result.k)
    return _scaled(_albedo([lambda t, o: single_albedo(single, t, o)], theta_deg), result.scale)


def _scaled(albedo: Albedo, scale: float) -> Albedo:
    """The albedo times the fit's scale factor."""
    return Albedo(albedo.theta_deg, tuple(scale * x for x in albedo.outside),
                  tuple(scale * x for x in albedo.inside))


@dataclass(frozen=True)
class Compensation:
    """What the plugin adds to the material at THETA_NODES_DEG (never below 0), and how far the
    material with it stays from the model's R + T, at the nodes and half-way between them."""

    added: Albedo
    worst_error: float  # relative, of R + T from outside
    worst_at_deg: float


def _between(nodes: np.ndarray) -> np.ndarray:
    """The nodes and the angles half-way between them, in order."""
    mids = 0.5 * (nodes[1:] + nodes[:-1])
    return np.sort(np.concatenate([nodes, mids]))


def compensation(result: FitResult) -> Compensation:
    """The plugin's tables for the fit and the worst relative error of R + T they leave."""
    angles = _between(np.array(THETA_NODES_DEG, dtype=float))
    model, material = model_albedo(result, angles), material_albedo(result, angles)
    gap = [tuple(np.maximum(m - b, 0.0) for m, b in zip(ms, bs, strict=True))
           for ms, bs in ((model.outside, material.outside), (model.inside, material.inside))]
    at_nodes = np.isin(angles, THETA_NODES_DEG)
    added = Albedo(angles[at_nodes], *(tuple(x[at_nodes] for x in side) for side in gap))
    interpolated = sum(np.interp(angles, added.theta_deg, x) for x in added.outside)
    error = np.abs(material.total() + interpolated - model.total()) / model.total()
    worst = int(np.argmax(error))
    return Compensation(added, float(error[worst]), float(angles[worst]))


def dropped_energy_line(result: FitResult) -> str:
    """One line: the share of the model's R + T that the single-scattering material keeps at
    REPORT_ANGLES_DEG."""
    angles = np.array(REPORT_ANGLES_DEG)
    kept = material_albedo(result, angles).total() / model_albedo(result, angles).total()
    return ("single scattering only: the material drops the fit's multiple scattering and keeps "
            + " / ".join(f"{k:.3f}" for k in kept) + " of the model's R + T at "
            + " / ".join(f"{a:g}" for a in angles) + " deg incidence")
