"""Smooth-interface optics the bench needs around the rough interface: Fresnel, Snell, half vectors.

The rough interface itself is model.bsdf's business; these describe the hemisphere's curved face
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


def coupled_direction(w: np.ndarray, h: np.ndarray, eta_w: float, eta_other: float,
                      reflect: bool) -> np.ndarray:
    """The direction that microfacet normal h couples to w: its mirror image (reflect) or its
    refraction from the medium of index eta_w into eta_other (mirror image under TIR)."""
    c = np.sum(w * h, axis=-1, keepdims=True)
    h = np.where(c < 0, -h, h)
    c = np.abs(c)
    mirror = 2.0 * c * h - w
    if reflect:
        return mirror
    eta = eta_w / eta_other
    k = 1.0 - eta**2 * (1.0 - c**2)
    refracted = -eta * w + (eta * c - np.sqrt(np.clip(k, 0.0, None))) * h
    return np.where(k > 0, refracted, mirror)


def min_stretch(w: np.ndarray, other: np.ndarray, eta_w: float, eta_other: float) -> float:
    """Smallest singular value of d(other)/dh at the h coupling w and other: the least angle
    `other` turns per radian of microfacet tilt (where a lobe in `other` is narrowest)."""
    reflect = bool(w[2] * other[2] > 0)
    h = half_vector(w, other, eta_w, eta_other)
    helper = np.array([1.0, 0.0, 0.0]) if abs(h[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(h, helper)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(h, e1)
    eps = 1e-6
    base = coupled_direction(w, h, eta_w, eta_other, reflect)
    columns = [(coupled_direction(w, (h + eps * e) / np.linalg.norm(h + eps * e), eta_w,
                                  eta_other, reflect) - base) / eps for e in (e1, e2)]
    return float(np.linalg.svd(np.stack(columns, axis=-1), compute_uv=False)[-1])
