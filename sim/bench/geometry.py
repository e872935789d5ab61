"""Stage positions -> lab directions -> sample-frame wi, wo (docs/architecture.md convention).

Written independently of gonio/geometry.py (plans -> stage angles); a test checks they agree.
Lab frame: Z up (the common rotation axis), X toward the source, Y = Z x X; the beam travels
along -X. Sample frame: z = sample normal n, x = t1, y = Z, then turned by the azimuth.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

TOWARD_SOURCE = np.array([1.0, 0.0, 0.0])  # lab direction from the sample to the source
BEAM_DIRECTION = -TOWARD_SOURCE  # the direction the incident beam travels


def detector_direction(arm_deg, elevation_deg=0.0) -> np.ndarray:
    """Lab unit vector from the sample to the detector: (cos e cos a, cos e sin a, sin e)."""
    a, e = np.radians(arm_deg), np.radians(elevation_deg)
    return np.stack(np.broadcast_arrays(np.cos(e) * np.cos(a), np.cos(e) * np.sin(a),
                                        np.sin(e)), axis=-1)


def lab_to_sample(v: np.ndarray, sample_deg, azimuth_deg=0.0, flipped=False) -> np.ndarray:
    """Sample-frame coordinates of lab vectors v (..., 3).

    (v.t1, v.Z, v.n) with n = (cos s, sin s, 0), t1 = (-sin s, cos s, 0), turned by the azimuth
    p. `flipped` mounts the sample the other way round (its exterior normal is -n, e.g. lit
    through the hemisphere): x and z change sign, a 180-degree turn about y.
    """
    s, p = np.radians(sample_deg), np.radians(azimuth_deg)
    x = -v[..., 0] * np.sin(s) + v[..., 1] * np.cos(s)
    y = v[..., 2]
    z = v[..., 0] * np.cos(s) + v[..., 1] * np.sin(s)
    if flipped:
        x, z = -x, -z
    xp = x * np.cos(p) + y * np.sin(p)
    yp = -x * np.sin(p) + y * np.cos(p)
    return np.stack(np.broadcast_arrays(xp, yp, z), axis=-1)


def sample_to_lab(w: np.ndarray, sample_deg, azimuth_deg=0.0, flipped=False) -> np.ndarray:
    """Inverse of `lab_to_sample`: lab vectors of sample-frame vectors w (..., 3)."""
    s, p = np.radians(sample_deg), np.radians(azimuth_deg)
    x = w[..., 0] * np.cos(p) - w[..., 1] * np.sin(p)
    y = w[..., 0] * np.sin(p) + w[..., 1] * np.cos(p)
    z = w[..., 2]
    if flipped:
        x, z = -x, -z
    lab_x = -x * np.sin(s) + z * np.cos(s)
    lab_y = x * np.cos(s) + z * np.sin(s)
    return np.stack(np.broadcast_arrays(lab_x, lab_y, y), axis=-1)


def sample_frame_directions(
    positions: Mapping[str, float], flipped: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """(wi, wo) in the sample frame for stage positions {"sample", "arm", "azimuth",
    "elevation"} in degrees (azimuth and elevation default to 0; values may be arrays)."""
    s = positions["sample"]
    p = positions.get("azimuth", 0.0)
    wi = lab_to_sample(TOWARD_SOURCE, s, p, flipped)
    wo = lab_to_sample(detector_direction(positions["arm"], positions.get("elevation", 0.0)),
                       s, p, flipped)
    wi, wo = np.broadcast_arrays(wi, wo)
    return wi, wo


def angle_from_beam_rad(arm_deg, elevation_deg=0.0) -> np.ndarray:
    """Angle between the detector direction and the straight-through beam (arm 180), rad."""
    d = detector_direction(arm_deg, elevation_deg)
    return np.arctan2(np.linalg.norm(np.cross(d, BEAM_DIRECTION), axis=-1), d @ BEAM_DIRECTION)
