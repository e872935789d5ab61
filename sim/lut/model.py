"""The split-sum integrands of gonio's rough dielectric (sim.bsdf), estimated by importance
sampling with the model's own sample(); smooth-surface limits in closed form.

The view direction v = (sqrt(1 - mu^2), 0, mu) is the model's wi. By the model's reciprocity
(f_t(l, v) / eta_v^2 = f_t(v, l) / eta_l^2, DESIGN.md) the renderer's integral over light
directions l equals the model's directional albedo from v times (n_view / n_beyond)^2.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim.bsdf import RoughDielectric
from sim.bsdf.fresnel import dielectric_reflectance_transmittance, fresnel_dielectric
from sim.bsdf.multiple_scattering import RandomWalkBSDF
from sim.lut.spec import CHANNELS, TableSpec

#: Below this alpha the surface is treated as smooth: the closed-form (delta) limit is used.
ALPHA_DELTA = 1e-7


def view_direction(mu: float) -> np.ndarray:
    """Unit view vector at cos(theta) = mu in the x-z plane (mu clipped to [0, 1])."""
    mu = min(max(float(mu), 0.0), 1.0)
    return np.array([np.sqrt((1.0 - mu) * (1.0 + mu)), 0.0, mu])


def smooth_limit(kind: str, mu: np.ndarray, eta: np.ndarray | float) -> np.ndarray:
    """The table's channels for a smooth interface (alpha -> 0), shape (..., channels).

    Reflection: a mirror has f_r / F * |cos o| / pdf = 1 at v.h = mu, so scale = 1 - (1-mu)^5
    and bias = (1-mu)^5. Transmission: (1 - F(mu, eta)) / eta^2, zero under TIR.
    """
    mu = np.asarray(mu, dtype=np.float64)
    if kind == "reflection":
        s5 = (1.0 - mu) ** 5
        return np.stack([1.0 - s5, s5], axis=-1)
    eta = np.asarray(eta, dtype=np.float64)
    return (dielectric_reflectance_transmittance(mu, eta)[1] / (eta * eta))[..., None]


@dataclass(frozen=True)
class ModelEstimator:
    """Estimator of a table's channels at (mu, alpha[, eta]) points from gonio's model."""

    kind: str
    distribution: str = "ggx"
    masking: str = "correlated"
    multiple_scattering: bool = False
    reflection_eta: float = 1.5

    @classmethod
    def for_spec(cls, spec: TableSpec) -> ModelEstimator:
        """The estimator a TableSpec asks for."""
        return cls(spec.kind, spec.distribution, spec.masking, spec.multiple_scattering,
                   spec.reflection_eta)

    @property
    def channels(self) -> tuple[str, ...]:
        """Channel names, as TableSpec.channels."""
        return CHANNELS[self.kind]

    @property
    def description(self) -> str:
        """The model and how it is used, for the table's metadata."""
        eta = (f"eta={self.reflection_eta} (cancels in f_r / F)" if self.kind == "reflection"
               else "eta = table eta = n_beyond / n_view, wi = view")
        walk = "RandomWalkBSDF (Heitz 2016) walks" if self.multiple_scattering else "sample()"
        return (f"sim.bsdf.RoughDielectric(distribution={self.distribution!r}, "
                f"masking={self.masking!r}, lobes=('{self.kind}',), "
                f"multiple_scattering={self.multiple_scattering}); {eta}; "
                f"importance sampling by {walk}; alpha < {ALPHA_DELTA:g}: smooth limit")

    def model(self, alpha: float, eta: float) -> RoughDielectric:
        """The single-lobe model at one (alpha, eta)."""
        return RoughDielectric(self.distribution, alpha=alpha, eta=eta, masking=self.masking,
                               lobes=(self.kind,))

    def __call__(self, params: np.ndarray, u: np.ndarray,
                 rng: np.random.Generator) -> np.ndarray:
        """Channels (m, channels) at params (m, 2 or 3) from the shared uniforms u (n, 3)."""
        out = np.empty((len(params), len(self.channels)))
        for j, row in enumerate(params):
            out[j] = self.entry(row, u, rng)
        return out

    def entry(self, row: np.ndarray, u: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Channels at one point (mu, alpha[, eta])."""
        mu, alpha = float(row[0]), float(row[1])
        eta = float(row[2]) if self.kind == "transmission" else self.reflection_eta
        if alpha < ALPHA_DELTA:
            return smooth_limit(self.kind, mu, eta)
        v = np.broadcast_to(view_direction(mu), u.shape)
        if self.kind == "reflection":
            wo, weight, _ = self.model(alpha, eta).sample(v, u)
            h = wo + v
            cos_vh = np.clip(np.einsum("ij,ij->i", h, v) / np.sqrt(np.einsum("ij,ij->i", h, h)),
                             0.0, 1.0)
            f = fresnel_dielectric(cos_vh, eta)
            unit_fresnel = np.where(weight > 0, weight / f, 0.0)
            s5 = (1.0 - cos_vh) ** 5
            return np.array([np.mean(unit_fresnel * (1.0 - s5)), np.mean(unit_fresnel * s5)])
        if self.multiple_scattering:
            walk = RandomWalkBSDF(self.model(alpha, eta), walks=1)
            wo, weight, _ = walk.sample(v, u, rng)
            weight = np.where(wo[:, 2] < 0, weight, 0.0)
        else:
            wo, weight, _ = self.model(alpha, eta).sample(v, u)
        return np.array([np.mean(weight) / (eta * eta)])
