"""Micro-BSDFs of the random walk (Heitz et al. 2016, section 5): conductor, dielectric, diffuse.

Each works in the local frame of the side the walk is on (z = macro-normal pointing into that
side's medium), with `w_in` pointing back along the arriving ray. `phase_*` are the phase
functions p(w_in -> w_out) in 1/sr (they integrate to the scattered energy, at most 1), `scatter`
draws the next direction. `unit=True` drops the energy factors (Fresnel of a conductor, albedo),
which gives the walk's own direction density, used for pdf().
"""

from __future__ import annotations

import numpy as np

from model.bsdf.distributions import Distribution
from model.bsdf.vectors import dot


def _normalize(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return v / n


def _reflect_phase(slopes: Distribution, w_in, w_out, fresnel) -> np.ndarray:
    """F D_visible(w_in, h) / (4 <w_in, h>) = F D(h) / (4 A(w_in)), h the half vector."""
    h = _normalize(w_in + w_out)
    c = dot(w_in, h)
    ok = (c > 0.0) & (h[..., 2] > 0.0)
    area = slopes.projected_area(w_in)
    with np.errstate(divide="ignore", invalid="ignore"):
        value = fresnel(np.where(ok, c, 1.0)) * slopes.D(h) / (4.0 * area)
    return np.where(ok & (area > 0.0), value, 0.0)


def _unit(cos: np.ndarray) -> np.ndarray:
    return np.ones_like(cos)


class MicroConductor:
    """Specular conductor facets with complex index eta_complex (None: perfect mirror, F = 1)."""

    transmits = False
    guidable = True

    def __init__(self, eta_complex: complex | None):
        self.eta_complex = eta_complex

    def local_eta(self, outside: np.ndarray) -> np.ndarray:
        """Relative index across the facets (unused by a conductor: ones)."""
        return np.ones(np.shape(outside))

    def fresnel(self, cos: np.ndarray) -> np.ndarray:
        """Facet reflectance at the cosine `cos`."""
        if self.eta_complex is None:
            return _unit(cos)
        from model.bsdf.fresnel import fresnel_conductor

        return fresnel_conductor(cos, self.eta_complex)

    def phase_reflect(self, slopes, w_in, w_out, outside, m, unit):
        """Reflection phase function."""
        return _reflect_phase(slopes, w_in, w_out, _unit if unit else self.fresnel)

    def scatter(self, slopes, w_in, m, outside, u, unit):
        """Mirror w_in about m; the energy factor is F."""
        c = dot(w_in, m)
        w_out = 2.0 * c[..., None] * m - w_in
        factor = _unit(c) if unit else self.fresnel(c)
        return w_out, factor, np.zeros(c.shape, dtype=bool)


class MicroDielectric:
    """Smooth dielectric facets, eta = n_interior / n_exterior; paths chosen by Fresnel."""

    transmits = True
    guidable = True

    def __init__(self, eta: float):
        self.eta = float(eta)

    def local_eta(self, outside: np.ndarray) -> np.ndarray:
        """n_other / n_this for a walk on the outside (True) or inside (False)."""
        return np.where(outside, self.eta, 1.0 / self.eta)

    def _fresnel(self, cos: np.ndarray, eta_local: np.ndarray) -> np.ndarray:
        from model.bsdf.fresnel import fresnel_dielectric

        return fresnel_dielectric(cos, eta_local)

    def phase_reflect(self, slopes, w_in, w_out, outside, m, unit):
        """F(<w_in,h>) D(h) / (4 A(w_in))."""
        eta_l = self.local_eta(outside)
        return _reflect_phase(slopes, w_in, w_out, lambda c: self._fresnel(c, eta_l))

    def phase_transmit(self, slopes, w_in, w_out, outside, unit):
        """(1-F) D_visible(w_in,h) eta^2 |<w_out,h>| / (<w_in,h> + eta <w_out,h>)^2; w_out below."""
        eta_l = self.local_eta(outside)
        h = -_normalize(w_in + eta_l[..., None] * w_out)
        h = h * np.where(h[..., 2] < 0.0, -1.0, 1.0)[..., None]
        ci = dot(w_in, h)
        co = dot(w_out, h)
        ok = (ci > 0.0) & (co < 0.0) & (h[..., 2] > 0.0)
        denom = ci + eta_l * co
        with np.errstate(divide="ignore", invalid="ignore"):
            value = (
                (1.0 - self._fresnel(np.where(ok, ci, 1.0), eta_l))
                * slopes.D_visible(w_in, h)
                * eta_l**2
                * np.abs(co)
                / (denom * denom)
            )
        return np.where(ok & np.isfinite(value), value, 0.0)

    def scatter(self, slopes, w_in, m, outside, u, unit):
        """Reflect with probability F, else refract (Snell); the energy factor is 1."""
        eta_l = self.local_eta(outside)
        c = np.clip(dot(w_in, m), 0.0, 1.0)
        f = self._fresnel(c, eta_l)
        sin2_t = (1.0 - c * c) / (eta_l * eta_l)
        cos_t = np.sqrt(np.maximum(0.0, 1.0 - sin2_t))
        crossed = (u[0] >= f) & (sin2_t < 1.0)
        reflected = 2.0 * c[..., None] * m - w_in
        refracted = -w_in / eta_l[..., None] + (c / eta_l - cos_t)[..., None] * m
        w_out = np.where(crossed[..., None], refracted, reflected)
        return _normalize(w_out), np.ones_like(c), crossed


class MicroDiffuse:
    """Lambertian facets of albedo `albedo`; the phase function is estimated with the sampled m."""

    transmits = False
    guidable = False

    def __init__(self, albedo: float):
        if not 0.0 <= albedo <= 1.0:
            raise ValueError(f"albedo must lie in [0, 1], got {albedo!r}")
        self.albedo = float(albedo)

    def phase_reflect(self, slopes, w_in, w_out, outside, m, unit):
        """Unbiased one-sample estimate albedo <w_out, m>+ / pi with m ~ D_visible(w_in)."""
        a = 1.0 if unit else self.albedo
        return a * np.maximum(dot(w_out, m), 0.0) / np.pi

    def scatter(self, slopes, w_in, m, outside, u, unit):
        """Cosine-weighted direction about m; the energy factor is the albedo."""
        t1 = _normalize(np.cross(np.where(np.abs(m[..., :1]) > 0.9, [0.0, 1.0, 0.0],
                                          [1.0, 0.0, 0.0]), m))
        t2 = np.cross(m, t1)
        r = np.sqrt(u[0])
        phi = 2.0 * np.pi * u[1]
        z = np.sqrt(np.maximum(0.0, 1.0 - u[0]))
        w_out = (r * np.cos(phi))[..., None] * t1 + (r * np.sin(phi))[..., None] * t2
        w_out = w_out + z[..., None] * m
        factor = np.full(m.shape[:-1], 1.0 if unit else self.albedo)
        return _normalize(w_out), factor, np.zeros(m.shape[:-1], dtype=bool)
