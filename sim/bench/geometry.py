"""Stage positions -> lab directions -> sample-frame wi, wo (docs/architecture.md convention).

Written independently of gonio/geometry.py (plans -> stage angles); a test checks they agree.
Lab frame: Z up (the common rotation axis), X toward the source, Y = Z x X; the beam travels
along -X. Sample frame: z = sample normal n, x = t1, y = Z, then turned by the azimuth.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

TOWARD_SOURCE = np.array([1.0, 0.0, 0.0])  # lab direction from the sample to the source
BEAM_DIRECTION = -TOWARD_SOURCE  # the direction the incident beam travels


def _sin_cos(deg):
    """(sin, cos) of angles in degrees: math for one number (a bench reading asks for one, and
    numpy's per-call cost is 20 times the sine's), numpy for arrays."""
    if isinstance(deg, float | int):
        r = math.radians(deg)
        return math.sin(r), math.cos(r)
    r = np.radians(deg)
    return np.sin(r), np.cos(r)


def _vector(x, y, z) -> np.ndarray:
    """Components (numbers or arrays, broadcast) stacked along a last axis of 3."""
    if isinstance(x, float) and isinstance(y, float) and isinstance(z, float):
        return np.array((x, y, z))
    return np.stack(np.broadcast_arrays(x, y, z), axis=-1)


def _detector_components(arm_deg, elevation_deg):
    """(x, y, z) of detector_direction: numbers for numbers, arrays otherwise."""
    (sin_a, cos_a), (sin_e, cos_e) = _sin_cos(arm_deg), _sin_cos(elevation_deg)
    return cos_e * cos_a, cos_e * sin_a, sin_e


def detector_direction(arm_deg, elevation_deg=0.0) -> np.ndarray:
    """Lab unit vector from the sample to the detector: (cos e cos a, cos e sin a, sin e)."""
    return _vector(*_detector_components(arm_deg, elevation_deg))


def _to_sample(x, y, z, sample_trig, azimuth_trig, flipped):
    """Sample-frame components of lab components (x, y, z), given (sin, cos) of the sample's
    and the azimuth's angles (lab_to_sample's formula)."""
    (sin_s, cos_s), (sin_p, cos_p) = sample_trig, azimuth_trig
    x, y, z = -x * sin_s + y * cos_s, z, x * cos_s + y * sin_s
    if flipped:
        x, z = -x, -z
    return x * cos_p + y * sin_p, -x * sin_p + y * cos_p, z


def lab_to_sample(v: np.ndarray, sample_deg, azimuth_deg=0.0, flipped=False) -> np.ndarray:
    """Sample-frame coordinates of lab vectors v (..., 3).

    (v.t1, v.Z, v.n) with n = (cos s, sin s, 0), t1 = (-sin s, cos s, 0), turned by the azimuth
    p. `flipped` mounts the sample the other way round (its exterior normal is -n, e.g. lit
    through the hemisphere): x and z change sign, a 180-degree turn about y.
    """
    return _vector(*_to_sample(v[..., 0], v[..., 1], v[..., 2], _sin_cos(sample_deg),
                               _sin_cos(azimuth_deg), flipped))


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
    rotation = _sin_cos(positions["sample"]), _sin_cos(positions.get("azimuth", 0.0))
    detector = _detector_components(positions["arm"], positions.get("elevation", 0.0))
    wi = _vector(*_to_sample(*TOWARD_SOURCE.tolist(), *rotation, flipped))
    wo = _vector(*_to_sample(*detector, *rotation, flipped))
    if wi.shape != wo.shape:
        wi, wo = np.broadcast_arrays(wi, wo)
    return wi, wo


def angle_from_beam_rad(arm_deg, elevation_deg=0.0) -> np.ndarray:
    """Angle between the detector direction and the straight-through beam (arm 180), rad."""
    d = detector_direction(arm_deg, elevation_deg)
    return np.arctan2(np.linalg.norm(np.cross(d, BEAM_DIRECTION), axis=-1), d @ BEAM_DIRECTION)
