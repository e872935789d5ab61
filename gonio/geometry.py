"""Stage angles <-> sample-frame directions, the convention of docs/architecture.md.

Lab frame: Z up (the common rotation axis), X toward the source. Sample stage s turns the
normal to (cos s, sin s, 0); the arm a and elevation e put the detector along
(cos e cos a, cos e sin a, sin e); the azimuth stage p turns the sample about its normal.
Everything is vectorised over numpy arrays and works in degrees at the edges.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike


class StageAngles(NamedTuple):
    """Stage positions in degrees (arrays of one shape)."""

    sample_deg: np.ndarray
    arm_deg: np.ndarray
    elevation_deg: np.ndarray
    azimuth_deg: np.ndarray


class SampleAngles(NamedTuple):
    """Spherical angles in the sample (BSDF) frame, degrees: theta from +z in [0, 180],
    phi = atan2(y, x) in (-180, 180]. theta_o > 90 is the transmitted side."""

    theta_i_deg: np.ndarray
    phi_i_deg: np.ndarray
    theta_o_deg: np.ndarray
    phi_o_deg: np.ndarray


def _to_sample_frame(v: np.ndarray, s: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Lab vectors (..., 3) -> sample-frame coordinates for sample angle s, azimuth p (rad)."""
    t1 = np.stack([-np.sin(s), np.cos(s), np.zeros_like(s)], axis=-1)
    n = np.stack([np.cos(s), np.sin(s), np.zeros_like(s)], axis=-1)
    x, y, z = np.sum(v * t1, axis=-1), v[..., 2], np.sum(v * n, axis=-1)
    cp, sp = np.cos(p), np.sin(p)
    return np.stack([x * cp + y * sp, -x * sp + y * cp, z], axis=-1)


def directions(sample_deg: ArrayLike, arm_deg: ArrayLike, elevation_deg: ArrayLike = 0.0,
               azimuth_deg: ArrayLike = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors (wi toward the source, wo toward the detector) in the sample frame."""
    s, a, e, p = np.broadcast_arrays(*(np.radians(np.asarray(x, dtype=np.float64))
                                       for x in (sample_deg, arm_deg, elevation_deg, azimuth_deg)))
    source = np.broadcast_to(np.array([1.0, 0.0, 0.0]), s.shape + (3,))
    detector = np.stack([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)], axis=-1)
    return _to_sample_frame(source, s, p), _to_sample_frame(detector, s, p)


def _one_to_sample_frame(v: tuple[float, float, float], s: float, p: float
                         ) -> tuple[float, float, float]:
    """_to_sample_frame for one lab vector and one stage pose (rad), on numbers: the same
    operations in the same order (the sum over the three components as numpy reduces it), so
    the result is the vectorised one bit for bit."""
    sin_s, cos_s = math.sin(s), math.cos(s)
    x = v[0] * -sin_s + ((0.0 + v[1] * cos_s) + v[2] * 0.0)
    z = v[0] * cos_s + ((0.0 + v[1] * sin_s) + v[2] * 0.0)
    cp, sp = math.cos(p), math.sin(p)
    return x * cp + v[2] * sp, -x * sp + v[2] * cp, z


def _one_sample_angles(sample_deg: float, arm_deg: float, elevation_deg: float,
                       azimuth_deg: float) -> SampleAngles:
    """sample_angles of one stage pose: a scan records one per reading, and numpy's per-call
    cost on single numbers is most of its time (atan2 and hypot stay numpy's: math's differ
    from them in the last bit)."""
    s, a, e, p = map(math.radians, (sample_deg, arm_deg, elevation_deg, azimuth_deg))
    detector = (math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e))
    out = []
    for w in (_one_to_sample_frame((1.0, 0.0, 0.0), s, p), _one_to_sample_frame(detector, s, p)):
        phi = math.degrees(float(np.arctan2(w[1], w[0])))
        out += [math.degrees(float(np.arctan2(float(np.hypot(w[0], w[1])), w[2]))),
                phi + 360.0 if phi <= -180.0 else phi]
    return SampleAngles(*out)


def sample_angles(sample_deg: ArrayLike, arm_deg: ArrayLike, elevation_deg: ArrayLike = 0.0,
                  azimuth_deg: ArrayLike = 0.0) -> SampleAngles:
    """Sample-frame spherical angles of the source and detector for given stage positions
    (numbers for numbers, arrays otherwise)."""
    if all(isinstance(x, float | int) for x in (sample_deg, arm_deg, elevation_deg,
                                                 azimuth_deg)):
        return _one_sample_angles(float(sample_deg), float(arm_deg), float(elevation_deg),
                                  float(azimuth_deg))
    wi, wo = directions(sample_deg, arm_deg, elevation_deg, azimuth_deg)

    def spherical(w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(theta, phi) in degrees; theta by atan2, accurate near the poles too."""
        theta = np.degrees(np.arctan2(np.hypot(w[..., 0], w[..., 1]), w[..., 2]))
        phi = np.degrees(np.arctan2(w[..., 1], w[..., 0]))
        return theta, np.where(phi <= -180.0, phi + 360.0, phi)

    return SampleAngles(*spherical(wi), *spherical(wo))


def stage_angles(theta_i_deg: ArrayLike, theta_o_deg: ArrayLike, phi_o_deg: ArrayLike = 0.0,
                 transmission: ArrayLike = False, azimuth_deg: ArrayLike = 0.0) -> StageAngles:
    """Stage positions for a plan point (vectorised).

    theta_i_deg is the signed sample angle (theta_i = |s|); theta_o_deg is measured from the
    normal on the chosen side (+z for reflection, -z for transmission), a negative value
    meaning the backward half of the plane of incidence; phi_o_deg is the azimuth from the
    forward direction of the plane of incidence (0 = specular / straight-through side,
    positive toward +Z). The arm comes back in (-180, 180].
    """
    s_deg = np.asarray(theta_i_deg, dtype=np.float64)
    t = np.radians(np.asarray(theta_o_deg, dtype=np.float64))
    phi = np.radians(np.asarray(phi_o_deg, dtype=np.float64))
    s_deg, t, phi, trans, p = np.broadcast_arrays(s_deg, t, phi,
                                                  np.asarray(transmission, dtype=bool),
                                                  np.asarray(azimuth_deg, dtype=np.float64))
    s = np.radians(s_deg)
    forward = np.where(s_deg < 0.0, -1.0, 1.0)  # decided in degrees: radians may underflow
    x = forward * np.sin(t) * np.cos(phi)
    y = np.sin(t) * np.sin(phi)
    z = np.where(trans, -1.0, 1.0) * np.cos(t)
    elevation = np.degrees(np.arcsin(np.clip(y, -1.0, 1.0)))
    arm = wrap_deg(np.degrees(s + np.arctan2(x, z)))
    return StageAngles(s_deg.astype(np.float64), arm, elevation, p.astype(np.float64))


def wrap_deg(angle_deg: ArrayLike) -> np.ndarray:
    """Angles wrapped into (-180, 180]."""
    a = np.mod(np.asarray(angle_deg, dtype=np.float64) + 180.0, 360.0) - 180.0
    return np.where(a <= -180.0, a + 360.0, a)


def into_limits(angle_deg: ArrayLike, limits: tuple[float, float]) -> np.ndarray:
    """The turn-equivalent (angle + 360 k) inside the limits that is nearest 0; NaN if none."""
    a = wrap_deg(angle_deg)
    lo, hi = limits
    candidates = np.stack([a, a - 360.0, a + 360.0])
    inside = (candidates >= lo - 1e-9) & (candidates <= hi + 1e-9)
    best = np.where(inside, np.abs(candidates), np.inf).argmin(axis=0)
    chosen = np.take_along_axis(candidates, best[None], axis=0)[0]
    return np.where(inside.any(axis=0), chosen, np.nan)
