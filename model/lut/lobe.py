"""Shape of the transmitted lobe, for the blur and direction tables: moments of the light
directions l weighted by f_t(l, v) |cos l| (the model's sample() from v, by reciprocity the
same lobe up to a constant), turned into the table's channels.

* Direction (`transmission-direction`, channel `offset`): the lobe's mean direction
  m = E[l] / |E[l]|, as a signed polar-angle offset from the ideal refraction (model.lut.direction).
* Blur (`transmission-blur`, channels `blur_alpha`, `residual`): the roughness of the
  reflection prefilter kernel (model.lut.prefilter) whose mean cosine about its axis equals the
  lobe's, E_k[d.l] = E[l.m] (= |E[l]|); `residual` is the relative mismatch of the second
  moment that the match leaves, E[1 - (l.m)^2] over the kernel's, minus 1.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from model.lut.direction import polar_angle, refraction_angle
from model.lut.model import ModelEstimator, view_direction
from model.lut.prefilter import equivalent_alpha, kernel_spreads
from model.lut.spec import CHANNELS, TableSpec

#: What each lobe table stores.
QUANTITIES = {"transmission-blur": "blur", "transmission-direction": "direction"}


def lobe_moments(wo: np.ndarray, weight: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Total weight (k,) and weighted mean direction vector E[l] (k, 3) of k lobes' samples
    wo (k, n, 3) with weights (k, n)."""
    total = weight.sum(axis=1)
    safe = np.where(total > 0, total, 1.0)[:, None]
    return total, np.einsum("kn,kni->ki", weight, wo) / safe


def blur_channels(alpha: float, wo: np.ndarray, weight: np.ndarray, total: np.ndarray,
                  first: np.ndarray) -> np.ndarray:
    """(blur_alpha, residual) per lobe (k, 2) from its samples and moments; a lobe that
    transmits nothing gets the albedo-only choice (blur_alpha = alpha, residual 0).
    1 - l.m = |l - m|^2 / 2 and 1 - (l.m)^2 = |l x m|^2 keep the digits of narrow lobes."""
    length = np.linalg.norm(first, axis=-1)
    axis = first / np.where(length > 0, length, 1.0)[:, None]
    safe = np.where(total > 0, total, 1.0)
    gap = wo - axis[:, None, :]
    one_minus_cos = 0.5 * np.einsum("kn,kn->k", weight, np.sum(gap * gap, axis=-1)) / safe
    cross = np.cross(wo, axis[:, None, :])
    spread = np.einsum("kn,kn->k", weight, np.sum(cross * cross, axis=-1)) / safe
    blur = equivalent_alpha(one_minus_cos)
    kernel_spread = kernel_spreads(blur)[1]
    # a lobe of one direction (a single transmitted sample, or an ideal refraction) is
    # matched by the delta kernel: residual 0
    point = (np.count_nonzero(weight > 0, axis=1) < 2) | (one_minus_cos <= 0)
    residual = np.where(point, 0.0, spread / np.where(point, 1.0, kernel_spread) - 1.0)
    empty = total <= 0
    return np.stack([np.where(empty, alpha, blur), np.where(empty, 0.0, residual)], axis=-1)


def direction_channels(mu: np.ndarray, eta: float, total: np.ndarray,
                       first: np.ndarray) -> np.ndarray:
    """(offset,) per lobe (k, 1): polar angle of the mean direction minus that of the ideal
    refraction, radians; 0 for a lobe that transmits nothing."""
    offset = polar_angle(first) - refraction_angle(mu, eta)
    return np.where(total > 0, offset, 0.0)[:, None]


@dataclass(frozen=True)
class LobeEstimator(ModelEstimator):
    """Estimator of the blur or direction table at (mu, alpha, eta) from the model's
    single-scattering transmission lobe (kind: the table kind, a key of QUANTITIES)."""

    @classmethod
    def for_spec(cls, spec: TableSpec) -> LobeEstimator:
        """The estimator of a blur or direction TableSpec."""
        if spec.kind not in QUANTITIES:
            raise ValueError(f"no lobe table of kind {spec.kind!r}")
        return cls(spec.kind, spec.distribution, spec.masking)

    @property
    def channels(self) -> tuple[str, ...]:
        """Channel names, as TableSpec.channels."""
        return CHANNELS[self.kind]

    @property
    def description(self) -> str:
        """The model and what is taken from its lobe, for the table's metadata."""
        return (f"model.bsdf.RoughDielectric(distribution={self.distribution!r}, "
                f"masking={self.masking!r}, lobes=('transmission',)); eta = table eta; "
                f"{QUANTITIES[self.kind]} from the moments of sample() from v "
                f"(model.lut.lobe); alpha below the smooth limit: 0")

    def model(self, alpha: float, eta: float):
        """The transmission-only model at one (alpha, eta)."""
        return ModelEstimator("transmission", self.distribution, self.masking,
                              backend=self.backend).model(alpha, eta)

    def smooth(self, mu: np.ndarray, eta: np.ndarray) -> np.ndarray:
        """A smooth surface refracts ideally: no blur, no residual, no offset."""
        return np.zeros((len(mu), len(self.channels)))

    def _single(self, mu: np.ndarray, alpha: float, eta: float, u: np.ndarray) -> np.ndarray:
        """The table's channels (k, channels) at k view angles sharing alpha and eta."""
        k, n = len(mu), len(u)
        v = np.repeat(view_direction(mu), n, axis=0)
        wo, weight, _ = self.model(alpha, eta).sample(v, np.tile(u, (k, 1)))
        wo, weight = wo.reshape(k, n, 3), weight.reshape(k, n)
        total, first = lobe_moments(wo, weight)
        if QUANTITIES[self.kind] == "blur":
            return blur_channels(alpha, wo, weight, total, first)
        return direction_channels(mu, eta, total, first)
