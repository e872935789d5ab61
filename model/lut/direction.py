"""Where the transmitted lobe looks: the ideal refraction direction of the view, and the
signed polar-angle offset of the lobe's mean direction from it (the direction table's value).

Light directions l on the far side are written by their polar angle theta from -N, in the
plane of incidence, on the side opposite the view (l = (-sin theta, 0, -cos theta) for the
view v = (sin theta_v, 0, cos theta_v)).
"""

from __future__ import annotations

import numpy as np


def refraction_angle(mu: np.ndarray, eta: np.ndarray | float) -> np.ndarray:
    """Polar angle of the ideal refraction of the view at N.V = mu into index ratio eta
    (sin theta_t = sin theta_v / eta); pi / 2 (grazing) under total internal reflection."""
    mu = np.clip(np.asarray(mu, dtype=np.float64), 0.0, 1.0)
    sin_t = np.sqrt((1.0 - mu) * (1.0 + mu)) / np.asarray(eta, dtype=np.float64)
    return np.arcsin(np.minimum(sin_t, 1.0))


def polar_angle(l: np.ndarray) -> np.ndarray:
    """Polar angle from -N of far-side directions l (..., 3) projected on the plane of
    incidence, positive on the side opposite the view."""
    return np.arctan2(-l[..., 0], -l[..., 2])


def far_side_direction(theta: np.ndarray) -> np.ndarray:
    """Unit far-side directions (..., 3) in the plane of incidence at polar angle theta
    (clipped to [0, pi / 2])."""
    theta = np.clip(np.asarray(theta, dtype=np.float64), 0.0, 0.5 * np.pi)
    return np.stack([-np.sin(theta), np.zeros_like(theta), -np.cos(theta)], axis=-1)


def lookup_direction(mu: np.ndarray, eta: np.ndarray | float,
                     offset: np.ndarray | float = 0.0) -> np.ndarray:
    """The direction a renderer fetches the prefiltered environment at: ideal refraction
    turned by offset (radians, away from the normal when positive)."""
    return far_side_direction(refraction_angle(mu, eta) + offset)
