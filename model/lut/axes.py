"""Table axes: each maps a physical parameter to a texture coordinate t in [0, 1].

Nodes sit at texel centres t = (k + 1/2) / n, the convention of a GPU sampler with
clamp-to-edge, so a renderer samples the table at t directly. On an axis with `ends` the outer
texel centres hold the ends of the parameter's range (node k at s = k / (n - 1) of it, so
t = (1/2 + (n - 1) s) / n and no lookup is clamped); without, s = t and the degenerate ends
(N.V = 0, roughness = 0) are not nodes. The N.V axis of a remapped transmission table has
ends and holds the remapped coordinate s (model.lut.remap), not N.V itself.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Largest index-of-refraction ratio on the eta axis; the axis spans [1/ETA_MAX, ETA_MAX].
ETA_MAX = 2.5
#: On an eta axis with ends, s - 1/2 goes as (ln eta)^ETA_POWER: nodes crowd towards eta = 1,
#: where grazing views see the transmittance change over |eta^2 - 1| ~ alpha^2.
ETA_POWER = 0.4


@dataclass(frozen=True)
class Axis:
    """One table axis: `name` of the parameter, `size` nodes, and how t maps to the parameter."""

    name: str
    size: int
    parameterisation: str
    ends: bool = False

    def coords(self) -> np.ndarray:
        """Texture coordinates of the nodes: texel centres (k + 1/2) / size."""
        return (np.arange(self.size, dtype=np.float64) + 0.5) / self.size

    def values(self) -> np.ndarray:
        """The parameter at the nodes."""
        return self.to_value(self.coords())

    def to_value(self, t: np.ndarray) -> np.ndarray:
        """Parameter at texture coordinate t."""
        t = np.asarray(t, dtype=np.float64)
        s = (t * self.size - 0.5) / (self.size - 1) if self.ends else t
        if self.name == "cos_theta":
            return s
        if self.name == "alpha":
            return s * s
        z = 2.0 * s - 1.0
        if self.ends:
            z = np.sign(z) * np.abs(z) ** (1.0 / ETA_POWER)
        return np.exp(math.log(ETA_MAX) * z)

    def to_coord(self, value: np.ndarray) -> np.ndarray:
        """Texture coordinate of a parameter value (the inverse of to_value, unclamped)."""
        v = np.asarray(value, dtype=np.float64)
        if self.name == "cos_theta":
            s = v
        elif self.name == "alpha":
            s = np.sqrt(v)
        else:
            z = np.log(v) / math.log(ETA_MAX)
            s = 0.5 * ((np.sign(z) * np.abs(z) ** ETA_POWER if self.ends else z) + 1.0)
        return (0.5 + (self.size - 1) * s) / self.size if self.ends else s


PARAMETERISATIONS = {
    "cos_theta": "s = cos(theta_i) = N.V",
    "alpha": "s = sqrt(alpha) (perceptual roughness; alpha = s^2)",
    "eta": f"s = (ln(eta) / ln({ETA_MAX}) + 1) / 2 (eta = {ETA_MAX}^(2s - 1))",
}
#: How t follows from s, without and with `ends`.
NODES = {False: "t = s; nodes at texel centres t = (k + 0.5) / size, clamp to edge",
         True: "t = (0.5 + (size - 1) s) / size: node k at s = k / (size - 1), the ends of "
               "the range on the outer texel centres (eta: s = (sign(z) |z|^"
               f"{ETA_POWER} + 1) / 2, z = ln(eta) / ln({ETA_MAX}))"}


def axes_for(kind: str, shape: tuple[int, ...], *, ends: bool = False,
             cos_theta: str | None = None) -> tuple[Axis, ...]:
    """The axes of a table of this kind and shape: (N.V, alpha) for reflection,
    (N.V, alpha, eta) for transmission; `ends` puts the ends of every range on nodes, and
    cos_theta, when given, describes a remapped N.V coordinate."""
    names = ("cos_theta", "alpha", "eta")[: len(shape)]
    described = {**PARAMETERISATIONS, **({"cos_theta": cos_theta} if cos_theta else {})}
    return tuple(Axis(name, n, described[name], ends)
                 for name, n in zip(names, shape, strict=True))
