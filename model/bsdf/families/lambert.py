"""Lambert: the ideal diffuse reflector, f = rho / pi, whose directional albedo is rho at every
incidence; sampled by the cosine-weighted hemisphere, so every sample's weight is rho."""

from __future__ import annotations

import math

import numpy as np

from model.bsdf.families.base import Parameter, ReflectionFamily

RHO = Parameter("rho", 0.0, 1.0, False, "albedo (directional-hemispherical reflectance)")


class Lambert(ReflectionFamily):
    """Ideal diffuse reflection of albedo rho (Lambert 1760), the `lambert` family."""

    family = "lambert"
    PARAMETERS = (RHO,)

    def __init__(self, rho: float = 0.8):
        super().__init__(rho=rho)

    def _eval(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        return np.full(len(wi), self.rho / math.pi)
