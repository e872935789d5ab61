"""Where a fit's residuals lie, in numbers that name what the model lacks: a floor above the model
far from the specular direction (a diffuse term, or multiple scattering when the floor is not
flat), an excess toward the source (Oren-Nayar's retro-reflection) and a lobe the model makes
too wide or too narrow (another distribution), or a peak a model without a lobe lacks. `gonio
fit`'s hints read them (gonio_cli.commands.fit.residual_hints)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from calibration.reduced import ReducedData

#: Reflected directions this far (deg) from the mirror direction and from the source are "far".
FAR_DEG = 25.0
#: Reflected directions this close (deg) to the source are not "far" (retro-reflection); the
#: far ones on the source's side against those forward tell back-scatter, at incidences from
#: RETRO_MIN_THETA_I on (nearer normal the two sides are alike).
RETRO_DEG = 15.0
RETRO_MIN_THETA_I = 20.0
#: A group's mean whitened residual counts when beyond this many of its standard errors and
#: beyond SIGNIFICANT in itself (a few points a sigma off are no pattern).
STANDARD_ERRORS = 3.0
SIGNIFICANT = 2.0
#: An excess whose spread over its mean is below this is flat (a Lambertian floor).
FLAT_SPREAD = 0.5
#: Fewest points a group needs to count.
MIN_POINTS = 4


def _angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.degrees(np.arccos(np.clip(np.sum(a * b, axis=-1), -1.0, 1.0)))


def _mean_if_significant(z: np.ndarray) -> float:
    """The mean of z if it stands out of its noise (STANDARD_ERRORS standard errors and
    SIGNIFICANT), else 0; 0 for fewer than MIN_POINTS."""
    if len(z) < MIN_POINTS:
        return 0.0
    mean = float(np.mean(z))
    error = float(np.std(z)) / math.sqrt(len(z))
    return mean if abs(mean) > max(STANDARD_ERRORS * error, SIGNIFICANT) else 0.0


def refracted(wi: np.ndarray, eta: float) -> np.ndarray:
    """The directions light from wi (N, 3) takes into a medium of relative index eta (> 1 has
    no total reflection from outside): t_xy = -wi_xy / eta, below the surface."""
    t_xy = -wi[:, :2] / eta
    return np.concatenate([t_xy, -np.sqrt(np.maximum(1.0 - np.sum(t_xy**2, axis=1,
                                                                    keepdims=True), 0.0))],
                          axis=1)


def _difference_if_significant(a: np.ndarray, b: np.ndarray) -> float:
    """mean(a) - mean(b) if it stands out of their noise as _mean_if_significant asks, else 0;
    0 for fewer than MIN_POINTS in either."""
    if min(len(a), len(b)) < MIN_POINTS:
        return 0.0
    difference = float(np.mean(a) - np.mean(b))
    error = math.hypot(float(np.std(a)) / math.sqrt(len(a)), float(np.std(b)) / math.sqrt(len(b)))
    return difference if abs(difference) > max(STANDARD_ERRORS * error, SIGNIFICANT) else 0.0


def residual_pattern(data: ReducedData, result: Any) -> dict[str, Any]:
    """The fitted model's residual pattern over the data's valid points (transmitted ones where
    the result has an index, about their refracted direction): `floor` the mean whitened
    residual far from the mirror (or refracted) direction, `floor_flat` whether the excess there
    is flat, `retro` the mean there on the source's side less that forward (back-scatter, at
    oblique incidence), `lobe` the mean near the
    mirror direction nearer its centre minus that farther out (> 0: the model's lobe is too wide,
    < 0: too narrow), `peak` the mean nearer its centre alone; each 0 where it does not stand
    out of the noise."""
    eta = float(getattr(result, "eta", math.nan))
    keep = (data.valid & np.isfinite(data.bsdf) & (data.sigma > 0)
            & (~data.transmission | math.isfinite(eta)))
    part = data.subset(keep)
    if not len(part.bsdf):
        return {"floor": 0.0, "floor_flat": False, "retro": 0.0, "lobe": 0.0, "peak": 0.0,
                "n": 0}
    model = result.predict(part.wi, part.wo)
    z = (part.bsdf - model) / part.sigma
    specular = np.where(part.transmission[:, None], refracted(part.wi, eta),
                        part.wi * np.array([-1.0, -1.0, 1.0]))
    from_mirror, from_source = _angle_deg(part.wo, specular), _angle_deg(part.wo, part.wi)
    far = (from_mirror > FAR_DEG) & (from_source > RETRO_DEG)
    floor = _mean_if_significant(z[far])
    excess = (part.bsdf - model)[far]
    flat = bool(floor > 0 and np.mean(excess) > 0
                and np.std(excess) < FLAT_SPREAD * np.mean(excess))
    oblique = far & (part.theta_i_deg >= RETRO_MIN_THETA_I) & ~part.transmission
    toward = np.sum(part.wo[:, :2] * part.wi[:, :2], axis=1) > 0
    retro = _difference_if_significant(z[oblique & toward], z[oblique & ~toward])
    near = from_mirror <= FAR_DEG
    lobe = peak = 0.0
    if np.count_nonzero(near) >= 2 * MIN_POINTS:
        inner = near & (from_mirror <= np.median(from_mirror[near]))
        outer = near & ~inner
        core, shoulder = _mean_if_significant(z[inner]), _mean_if_significant(z[outer])
        peak = core
        if core * shoulder < 0:  # opposite signs: the lobe's width, not its height
            lobe = core - shoulder
    return {"floor": floor, "floor_flat": flat, "retro": retro, "lobe": lobe, "peak": peak,
            "n": int(len(z))}
