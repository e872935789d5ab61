"""The split-sum approximation of rough glass end to end, against brute force, in a procedural
environment: a sky gradient, a sun disk and a checker wall on the far side of the surface.

Brute force: L(v) = integral of f_t(l, v) |cos l| L_env(l) dl = (1 / eta^2) times the same
integral of the model's f_t(v, l) (reciprocity, docs/lut.md), by the model's sample() from v
for the sky and wall, and for the sun disk by multiple importance sampling (balance heuristic)
of sample() and directions uniform in the disk.
Split sum: L(v) ~ T(mu, alpha, eta) * P(d, alpha_b), with P the prefiltered environment
(model.lut.prefilter's kernel, evaluated at the lookup by the same two-strategy estimate, so the
environment's own discretisation adds nothing), d the ideal refraction turned by the direction
table's offset (or not) and alpha_b the blur table's roughness (or the surface's alpha).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from model.bsdf.distributions import make_distribution
from model.bsdf.vectors import dot, unit
from model.lut.model import ModelEstimator, view_direction
from model.lut.prefilter import normalisation
from model.optics.quadrature import cap_solid_angle, orthonormal_basis

#: Below this prefilter roughness the kernel is a delta: P(d) = L_env(d).
BLUR_DELTA = 1e-6


@dataclass(frozen=True)
class Environment:
    """Radiance over far-side directions (z < 0, 'up' = -N): a sky darkening from the horizon
    to the zenith, a checker wall of `checker` degree cells within `wall_azimuth` degrees of
    the refraction side (azimuth 180) below `wall_elevation`, and a sun disk."""

    sun_elevation: float = 55.0  # degrees
    sun_azimuth: float = 180.0  # degrees; 180 is the plane of incidence, refraction side
    sun_radius: float = 1.0  # degrees
    sun_radiance: float = 1000.0
    wall_elevation: float = 30.0
    wall_azimuth: float = 70.0
    checker: float = 8.0
    ground: float = 0.05  # radiance on the viewer's side (never reached by transmission)

    @property
    def sun_direction(self) -> np.ndarray:
        """Unit direction (3,) of the sun's centre."""
        e, a = math.radians(self.sun_elevation), math.radians(self.sun_azimuth)
        return np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), -math.sin(e)])

    @property
    def sun_solid_angle(self) -> float:
        """Solid angle of the sun disk, sr."""
        return cap_solid_angle(math.radians(self.sun_radius))

    def in_sun(self, l: np.ndarray) -> np.ndarray:
        """True for directions inside the sun disk."""
        return dot(l, self.sun_direction) >= math.cos(math.radians(self.sun_radius))

    def base(self, l: np.ndarray) -> np.ndarray:
        """Radiance of the sky, wall and ground (everything but the sun) at unit l (..., 3)."""
        elevation = np.degrees(np.arcsin(np.clip(-l[..., 2], -1.0, 1.0)))
        azimuth = np.degrees(np.arctan2(l[..., 1], l[..., 0])) % 360.0
        sky = 0.25 + 1.0 * (1.0 - np.clip(elevation, 0.0, 90.0) / 90.0) ** 2
        cells = np.floor(azimuth / self.checker) + np.floor(elevation / self.checker)
        wall = (np.abs(azimuth - 180.0) <= self.wall_azimuth) & (elevation < self.wall_elevation)
        out = np.where(wall, np.where(cells % 2 == 0, 1.6, 0.08), sky)
        return np.where(elevation >= 0.0, out, self.ground)

    def radiance(self, l: np.ndarray) -> np.ndarray:
        """Total radiance at unit l (..., 3), the sun included."""
        return self.base(l) + np.where(self.in_sun(l), self.sun_radiance, 0.0)

    def sun_samples(self, u: np.ndarray) -> np.ndarray:
        """Directions (n, 3) uniform over the sun disk from uniforms u (n, 2)."""
        cos_r = math.cos(math.radians(self.sun_radius))
        cos_t = 1.0 - u[:, 0] * (1.0 - cos_r)
        sin_t = np.sqrt(np.maximum(1.0 - cos_t * cos_t, 0.0))
        phi = 2.0 * math.pi * u[:, 1]
        s = self.sun_direction
        e1, e2 = orthonormal_basis(s)
        return (cos_t[:, None] * s + (sin_t * np.cos(phi))[:, None] * e1
                + (sin_t * np.sin(phi))[:, None] * e2)


def sun_mis(env: Environment, f_lobe: np.ndarray, pdf_lobe: np.ndarray, hit: np.ndarray,
            f_disk: np.ndarray, pdf_disk_lobe: np.ndarray) -> float:
    """The sun's share of an integral of f L_env by the balance heuristic of n1 lobe samples
    (integrand f_lobe, density pdf_lobe, hit: inside the disk) and n2 disk samples (integrand
    f_disk, lobe density there pdf_disk_lobe); f without the sun's radiance."""
    n1, n2 = len(f_lobe), len(f_disk)
    uniform = 1.0 / env.sun_solid_angle
    lobe = np.where(hit, f_lobe / (n1 * pdf_lobe + n2 * uniform), 0.0)
    disk = f_disk / (n1 * pdf_disk_lobe + n2 * uniform)
    return float(env.sun_radiance * (lobe.sum() + disk.sum()))


def prefiltered(env: Environment, d: np.ndarray, alpha: float, u: np.ndarray,
                u_sun: np.ndarray) -> float:
    """P(d, alpha): the environment seen through the reflection prefilter kernel about the
    unit direction d (3,), from kernel samples u (n, 2) and disk samples u_sun (m, 2)."""
    if alpha < BLUR_DELTA:
        return float(env.radiance(d))
    ggx = make_distribution("ggx", alpha)
    e1, e2 = orthonormal_basis(d)
    frame = np.stack([e1, e2, d])  # rows: local x, y, z about d
    h = ggx.sample_normal(u[:, 0], u[:, 1]) @ frame
    l = 2.0 * dot(h, d)[:, None] * h - d
    norm = float(normalisation(alpha))
    cos_l = np.maximum(l @ d, 0.0)
    base = float(np.mean(cos_l * env.base(l))) / norm
    pdf = ggx.D(h @ frame.T) / 4.0  # density of l = reflect(d, h), h ~ D(h) cos theta_h
    disk = env.sun_samples(u_sun)
    disk_h = unit(disk + d)
    disk_pdf = ggx.D(disk_h @ frame.T) / 4.0
    return base + sun_mis(env, cos_l * pdf / norm, pdf, env.in_sun(l),
                          np.maximum(disk @ d, 0.0) * disk_pdf / norm, disk_pdf)


def brute_force(env: Environment, mu: float, alpha: float, eta: float, u: np.ndarray,
                u_sun: np.ndarray, distribution: str = "ggx",
                masking: str = "correlated") -> float:
    """The transmitted radiance toward the view at N.V = mu through the model at (alpha, eta):
    lobe samples u (n, 3) for everything, disk samples u_sun (m, 2) for the sun (MIS)."""
    model = ModelEstimator("transmission", distribution, masking).model(alpha, eta)
    v = view_direction(mu)
    wo, weight, pdf = model.sample(np.broadcast_to(v, u.shape), u)
    ok = weight > 0
    base = float(np.mean(np.where(ok, weight * env.base(np.where(ok[:, None], wo, -v)), 0.0)))
    disk = env.sun_samples(u_sun)
    vs = np.broadcast_to(v, disk.shape)
    f_disk = model.eval(vs, disk) * np.abs(disk[:, 2])
    sun = sun_mis(env, weight * pdf, np.where(ok, pdf, 1.0), ok & env.in_sun(wo), f_disk,
                  model.pdf(vs, disk))
    return (base + sun) / (eta * eta)
