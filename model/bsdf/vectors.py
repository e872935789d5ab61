"""Small vector helpers for the BSDF code: dot products, normalisation, input checking."""

from __future__ import annotations

import numpy as np


def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Dot product over the last axis."""
    return np.einsum("...i,...i->...", a, b)


def unit(v: np.ndarray) -> np.ndarray:
    """v scaled to unit length along the last axis (zero vectors stay zero)."""
    n = np.sqrt(dot(v, v))
    return v * (1.0 / np.where(n > 0, n, 1.0))[..., None]


def direction_arrays(*vs: np.ndarray) -> tuple[np.ndarray, ...]:
    """Broadcast direction arrays (..., 3) to one shape, float64, not normalised.

    Read-only views, never copies (a single direction against many stays one row in memory)."""
    arrays = [np.asarray(v, dtype=np.float64) for v in vs]
    for a in arrays:
        if a.ndim == 0 or a.shape[-1] != 3:
            raise ValueError(f"directions must have shape (..., 3), got {a.shape}")
    shape = np.broadcast_shapes(*(a.shape for a in arrays))
    return tuple(np.broadcast_to(a, shape) for a in arrays)


def directions(*vs: np.ndarray) -> tuple[np.ndarray, ...]:
    """Broadcast direction arrays (..., 3) to one shape, normalised, float64."""
    return tuple(unit(a) for a in direction_arrays(*vs))
