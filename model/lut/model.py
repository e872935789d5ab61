"""The split-sum integrands of gonio's rough dielectric (model.bsdf), estimated by importance
sampling with the model's own sample(); smooth-surface limits in closed form.

The view direction v = (sqrt(1 - mu^2), 0, mu) is the model's wi. By the model's reciprocity
(f_t(l, v) / eta_v^2 = f_t(v, l) / eta_l^2, docs/architecture.md) the renderer's integral over light
directions l equals the model's directional albedo from v times (n_view / n_beyond)^2.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from model.bsdf import RoughDielectric
from model.bsdf.fresnel import dielectric_reflectance_transmittance, fresnel_dielectric
from model.bsdf.multiple_scattering import RandomWalkBSDF
from model.lut.spec import CHANNELS, TableSpec

#: Below this alpha the surface is treated as smooth: the closed-form (delta) limit is used.
ALPHA_DELTA = 1e-7


def view_direction(mu: np.ndarray | float) -> np.ndarray:
    """Unit view vectors (..., 3) at cos(theta) = mu in the x-z plane (mu clipped to [0, 1])."""
    mu = np.clip(np.asarray(mu, dtype=np.float64), 0.0, 1.0)
    return np.stack([np.sqrt((1.0 - mu) * (1.0 + mu)), np.zeros_like(mu), mu], axis=-1)


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
    backend: str | None = None  # RoughDielectric's: None = compiled kernels, "numpy" = reference

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
        return (f"model.bsdf.RoughDielectric(distribution={self.distribution!r}, "
                f"masking={self.masking!r}, lobes=('{self.kind}',), "
                f"multiple_scattering={self.multiple_scattering}); {eta}; "
                f"importance sampling by {walk}; alpha < {ALPHA_DELTA:g}: smooth limit")

    def model(self, alpha: float, eta: float) -> RoughDielectric:
        """The single-lobe model at one (alpha, eta)."""
        return RoughDielectric(self.distribution, alpha=alpha, eta=eta, masking=self.masking,
                               lobes=(self.kind,), backend=self.backend)

    def smooth(self, mu: np.ndarray, eta: np.ndarray) -> np.ndarray:
        """The channels (k, channels) for a smooth interface: smooth_limit."""
        return smooth_limit(self.kind, mu, eta)

    def __call__(self, params: np.ndarray, u: np.ndarray,
                 rng: np.random.Generator) -> np.ndarray:
        """Channels (m, channels) at params (m, 2 or 3) from the shared uniforms u (n, 3):
        smooth limits where alpha < ALPHA_DELTA, else one scalar-alpha model per distinct
        (alpha, eta), whose sample() runs in model.bsdf's compiled kernels."""
        params = np.asarray(params, dtype=np.float64)
        mu, alpha = params[:, 0], params[:, 1]
        eta = params[:, 2] if self.kind != "reflection" else np.full(len(mu),
                                                                       self.reflection_eta)
        out = np.empty((len(params), len(self.channels)))
        smooth = alpha < ALPHA_DELTA
        out[smooth] = self.smooth(mu[smooth], eta[smooth])
        if self.multiple_scattering:
            for j in np.flatnonzero(~smooth):
                out[j] = self._walks(mu[j], alpha[j], eta[j], u, rng)
            return out
        rough = np.flatnonzero(~smooth)
        pairs, group = np.unique(np.column_stack([alpha[rough], eta[rough]]), axis=0,
                                 return_inverse=True)
        for g, (a, e) in enumerate(pairs):
            rows = rough[group.ravel() == g]
            out[rows] = self._single(mu[rows], float(a), float(e), u)
        return out

    def _single(self, mu: np.ndarray, alpha: float, eta: float, u: np.ndarray) -> np.ndarray:
        """Single-scattering channels (k, channels) at k view angles sharing alpha and eta."""
        k, n = len(mu), len(u)
        v = np.repeat(view_direction(mu), n, axis=0)
        wo, weight, _ = self.model(alpha, eta).sample(v, np.tile(u, (k, 1)))
        if self.kind == "transmission":
            return (weight.reshape(k, n).mean(axis=1) / (eta * eta))[:, None]
        h = wo + v
        cos_vh = np.clip(np.einsum("ij,ij->i", h, v) / np.sqrt(np.einsum("ij,ij->i", h, h)),
                         0.0, 1.0)
        unit_fresnel = np.where(weight > 0, weight / fresnel_dielectric(cos_vh, eta), 0.0)
        s5 = (1.0 - cos_vh) ** 5
        return np.stack([(unit_fresnel * (1.0 - s5)).reshape(k, n).mean(axis=1),
                         (unit_fresnel * s5).reshape(k, n).mean(axis=1)], axis=-1)

    def _walks(self, mu: float, alpha: float, eta: float, u: np.ndarray,
               rng: np.random.Generator) -> np.ndarray:
        """Multiple-scattering transmission at one point: the share of random walks from v
        leaving through the far side, times their throughput, over eta^2."""
        v = np.broadcast_to(view_direction(mu), u.shape)
        walk = RandomWalkBSDF(self.model(alpha, eta), walks=1)
        wo, weight = walk.walk_once(v, u, rng)
        return np.array([np.mean(np.where(wo[:, 2] < 0, weight, 0.0)) / (eta * eta)])
