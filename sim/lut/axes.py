"""Table axes: each maps a physical parameter to a texture coordinate t in [0, 1].

Nodes sit at texel centres t = (k + 1/2) / n, the convention of a GPU sampler with
clamp-to-edge, so a renderer samples the table at t directly and never needs a node at the
degenerate ends (N.V = 0, roughness = 0, eta = 1 are not nodes).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Largest index-of-refraction ratio on the eta axis; the axis spans [1/ETA_MAX, ETA_MAX].
ETA_MAX = 2.5


@dataclass(frozen=True)
class Axis:
    """One table axis: `name` of the parameter, `size` nodes, and how t maps to the parameter."""

    name: str
    size: int
    parameterisation: str

    def coords(self) -> np.ndarray:
        """Texture coordinates of the nodes: texel centres (k + 1/2) / size."""
        return (np.arange(self.size, dtype=np.float64) + 0.5) / self.size

    def values(self) -> np.ndarray:
        """The parameter at the nodes."""
        return self.to_value(self.coords())

    def to_value(self, t: np.ndarray) -> np.ndarray:
        """Parameter at texture coordinate t."""
        t = np.asarray(t, dtype=np.float64)
        if self.name == "cos_theta":
            return t
        if self.name == "alpha":
            return t * t
        return np.exp(math.log(ETA_MAX) * (2.0 * t - 1.0))

    def to_coord(self, value: np.ndarray) -> np.ndarray:
        """Texture coordinate of a parameter value (the inverse of to_value, unclamped)."""
        v = np.asarray(value, dtype=np.float64)
        if self.name == "cos_theta":
            return v
        if self.name == "alpha":
            return np.sqrt(v)
        return 0.5 * (np.log(v) / math.log(ETA_MAX) + 1.0)


PARAMETERISATIONS = {
    "cos_theta": "t = cos(theta_i) = N.V",
    "alpha": "t = sqrt(alpha) (perceptual roughness; alpha = t^2)",
    "eta": f"t = (ln(eta) / ln({ETA_MAX}) + 1) / 2 (eta = {ETA_MAX}^(2t - 1))",
}


def axes_for(kind: str, shape: tuple[int, ...]) -> tuple[Axis, ...]:
    """The axes of a table of this kind and shape: (N.V, alpha) for reflection,
    (N.V, alpha, eta) for transmission."""
    names = ("cos_theta", "alpha", "eta")[: len(shape)]
    return tuple(Axis(name, n, PARAMETERISATIONS[name])
                 for name, n in zip(names, shape, strict=True))
