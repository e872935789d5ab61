"""Oren-Nayar: diffuse reflection from a rough surface of Lambertian V-cavities whose facet
slopes have the standard deviation sigma (radians), with masking, shadowing and one
interreflection between facets; it brightens toward retro-reflection, which Lambert cannot.

M. Oren and S. K. Nayar, "Generalization of Lambert's reflectance model", SIGGRAPH '94,
pp. 239-246. variant='full' is the paper's functional approximation of the rough surface,
direct term L1 (coefficients C1, C2, C3) plus interreflection term L2 (0.17 rho^2 ...);
variant='qualitative' is the paper's simplified qualitative model (coefficients A, B) without
interreflection. Both are reciprocal; neither conserves energy: at rho = 1 the qualitative
model reflects 0.62-1.007 and the full model 0.77-1.032 over sigma <= 1 rad and all incidences
(docs/bsdf-families.md tabulates the directional albedo)."""

from __future__ import annotations

import math

import numpy as np

from model.bsdf.families.base import Parameter, ReflectionFamily
from model.bsdf.families.lambert import RHO

SIGMA = Parameter("sigma", 0.0, math.pi / 2, False,
                  "standard deviation of the facet slope angle, radians")
VARIANTS = ("full", "qualitative")


def polar_angles(wi: np.ndarray, wo: np.ndarray):
    """(theta_i, theta_o, cos(phi_o - phi_i)) of unit directions above the surface; the
    azimuth cosine is 0 where either direction is the normal (every term it multiplies then
    vanishes)."""
    si = np.hypot(wi[:, 0], wi[:, 1])
    so = np.hypot(wo[:, 0], wo[:, 1])
    sin_product = si * so
    live = sin_product > 0
    cos_phi = np.where(live, (wi[:, 0] * wo[:, 0] + wi[:, 1] * wo[:, 1])
                       / np.where(live, sin_product, 1.0), 0.0)
    return np.arctan2(si, wi[:, 2]), np.arctan2(so, wo[:, 2]), np.clip(cos_phi, -1.0, 1.0)


class OrenNayar(ReflectionFamily):
    """Oren-Nayar rough diffuse reflection (rho, sigma), the `oren-nayar` family."""

    family = "oren-nayar"
    PARAMETERS = (RHO, SIGMA)
    SETTINGS = ("variant",)

    def __init__(self, rho: float = 0.8, sigma: float = 0.3, variant: str = "full"):
        if variant not in VARIANTS:
            raise ValueError(f"variant must be one of {VARIANTS}, got {variant!r}")
        self.variant = variant
        super().__init__(rho=rho, sigma=sigma)

    def _eval(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        theta_i, theta_o, cos_phi = polar_angles(wi, wo)
        a, b = np.maximum(theta_i, theta_o), np.minimum(theta_i, theta_o)
        s2 = self.sigma * self.sigma
        if self.variant == "qualitative":
            big_a = 1.0 - 0.5 * s2 / (s2 + 0.33)
            big_b = 0.45 * s2 / (s2 + 0.09)
            return self.rho / math.pi * (big_a + big_b * np.maximum(cos_phi, 0.0)
                                         * np.sin(a) * np.tan(b))
        c1 = 1.0 - 0.5 * s2 / (s2 + 0.33)
        c2 = 0.45 * s2 / (s2 + 0.09) * np.where(cos_phi >= 0.0, np.sin(a),
                                                 np.sin(a) - (2.0 * b / math.pi) ** 3)
        c3 = 0.125 * s2 / (s2 + 0.09) * (4.0 * a * b / math.pi**2) ** 2
        direct = c1 + cos_phi * c2 * np.tan(b) + (1.0 - np.abs(cos_phi)) * c3 * np.tan(
            0.5 * (a + b))
        inter = (0.17 * self.rho * s2 / (s2 + 0.13)
                 * (1.0 - cos_phi * (2.0 * b / math.pi) ** 2))
        return self.rho / math.pi * (direct + inter)
