"""Smooth-interface optics the bench needs around the rough interface: Fresnel, Snell, half vectors.

The rough interface itself is sim.bsdf's business; these describe the hemisphere's curved face
(normal incidence), a slab's polished back face, and the lobe geometry used to choose quadrature
orders. Directions are unit vectors in the sample frame (+z exterior), vectorised over (..., 3).
"""

from __future__ import annotations

import numpy as np


def fresnel_dielectric(cos_i: np.ndarray, eta: float) -> np.ndarray:
    """Unpolarised Fresnel reflectance for light arriving with |cos| = cos_i on an interface
    where eta = n_transmitted / n_incident; 1 under total internal reflection."""
    cos_i = np.clip(np.abs(cos_i), 0.0, 1.0)
    sin2_t = (1.0 - cos_i**2) / eta**2
    cos_t = np.sqrt(np.clip(1.0 - sin2_t, 0.0, None))
    rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t)
    rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t)
    return np.where(sin2_t >= 1.0, 1.0, 0.5 * (rs**2 + rp**2))


def normal_transmittance(n: float) -> float:
    """Fresnel transmittance at normal incidence, 1 - ((n - 1) / (n + 1))^2."""
    return 1.0 - ((n - 1.0) / (n + 1.0)) ** 2


def air_to_glass_direction(w_air: np.ndarray, n: float) -> np.ndarray:
    """Direction inside a glass slab (index n) that leaves its flat back face (z = const)
    along w_air (z < 0): the same tangential part divided by n (always possible)."""
    xy = w_air[..., :2] / n
    z = -np.sqrt(np.clip(1.0 - np.sum(xy**2, axis=-1), 0.0, None))
    return np.concatenate([xy, z[..., None]], axis=-1)


def half_vector(wi: np.ndarray, wo: np.ndarray, eta_i: float, eta_o: float) -> np.ndarray:
    """Microfacet normal that couples wi and wo, oriented to +z: wi + wo for reflection
    (eta_i == eta_o side), -(eta_i wi + eta_o wo) for refraction (Walter's generalised h)."""
    same_side = wi[..., 2] * wo[..., 2] > 0
    h = np.where(same_side[..., None], wi + wo, -(eta_i * wi + eta_o * wo))
    h = h / np.maximum(np.linalg.norm(h, axis=-1, keepdims=True), 1e-300)
    return np.where(h[..., 2:3] < 0, -h, h)


def half_vector_jacobian(
    wi: np.ndarray, wo: np.ndarray, h: np.ndarray, eta_i: float, eta_o: float
) -> np.ndarray:
    """d omega_o / d omega_h: 4 |o.h| for reflection, (eta_i i.h + eta_o o.h)^2 / (eta_o^2 |o.h|)
    for refraction (Walter 2007, eqs. 14 and 16); swap the roles for d omega_i / d omega_h."""
    ih, oh = np.sum(wi * h, axis=-1), np.sum(wo * h, axis=-1)
    same_side = wi[..., 2] * wo[..., 2] > 0
    refl = 4.0 * np.abs(oh)
    refr = (eta_i * ih + eta_o * oh) ** 2 / np.maximum(eta_o**2 * np.abs(oh), 1e-300)
    return np.where(same_side, refl, refr)
