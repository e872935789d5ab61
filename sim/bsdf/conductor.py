"""RoughConductor: microfacet reflection off a rough conductor of complex index n + ik (or F = 1).

Opaque: only pairs with both directions above the surface (+z) scatter."""

from __future__ import annotations

import cmath

import numpy as np

from sim.bsdf.fresnel import fresnel_conductor
from sim.bsdf.microfacet import COS_HORIZON, MicrofacetModel, half_vector, reflect
from sim.bsdf.vectors import dot, unit


class RoughConductor(MicrofacetModel):
    """Rough conductor; eta_complex is n + ik relative to the exterior, None for F = 1.

    backend as for RoughDielectric (compiled kernel when available, 'numpy' the reference)."""

    def __init__(
        self,
        distribution: str = "ggx",
        alpha=0.1,
        eta_complex: complex | None = None,
        masking: str = "separable",
        sampling: str | None = None,
        multiple_scattering: bool = False,
        backend: str | None = None,
    ):
        if eta_complex is not None:
            try:
                eta_complex = complex(eta_complex)
            except (TypeError, ValueError):
                raise ValueError(
                    f"eta_complex must be a complex number n+ik or None, got {eta_complex!r}"
                ) from None
            if not (cmath.isfinite(eta_complex) and eta_complex.real > 0
                    and eta_complex.imag >= 0):
                raise ValueError(f"eta_complex must have n > 0 and k >= 0, got {eta_complex!r}")
        self.eta_complex = eta_complex
        super().__init__(distribution, alpha, masking, sampling, multiple_scattering, backend)

    def __repr__(self) -> str:
        return (f"RoughConductor({self.distribution!r}, eta_complex={self.eta_complex}, "
                f"masking={self.masking!r}, sampling={self.sampling!r})")

    def _kernel(self, wi, wo, want_pdf):
        from sim.bsdf.kernels import conductor

        dist, ax, ay, masking, sampling = self._kernel_codes()
        n = 0j if self.eta_complex is None else self.eta_complex
        return conductor(wi, wo, dist, ax, ay, self.eta_complex is not None, n, masking, sampling,
                         want_pdf)

    def _fresnel(self, cos_im):
        if self.eta_complex is None:
            return np.ones_like(cos_im)
        return fresnel_conductor(cos_im, self.eta_complex)

    @staticmethod
    def _live(wi, wo):
        return (wi[..., 2] > COS_HORIZON) & (wo[..., 2] > COS_HORIZON)

    def _eval(self, wi, wo):
        live = self._live(wi, wo)
        f = np.zeros(wi.shape[:-1])
        if live.any():
            wi, wo = wi[live], wo[live]
            m = half_vector(wi, wo)
            f[live] = (0.25 * self._fresnel(dot(wi, m)) * self.distribution.D(m)
                       * self._g2_over_cosines(wi, wo))
        return f

    def _pdf(self, wi, wo):
        live = self._live(wi, wo)
        p = np.zeros(wi.shape[:-1])
        if live.any():
            wi, wo = wi[live], wo[live]
            m = half_vector(wi, wo)
            p[live] = self._normal_pdf(wi, m) / (4.0 * dot(wo, m))
        return p

    def _sample(self, wi, u):
        if self._compiled_sampling():
            from sim.bsdf.kernels import conductor_sample

            dist, ax, ay, masking, sampling = self._kernel_codes()
            n = 0j if self.eta_complex is None else self.eta_complex
            return conductor_sample(wi, u, dist, ax, ay, self.eta_complex is not None, n,
                                    masking, sampling)
        wi = unit(wi)
        up = wi[:, 2] > COS_HORIZON
        wi = np.where(up[:, None], wi, [0.0, 0.0, 1.0])  # below the surface: fails below
        m = self._sample_normal(wi, u[:, 0], u[:, 1])
        c = dot(wi, m)
        wo = reflect(wi, m)
        ok = up & (c > 0) & (wo[:, 2] > COS_HORIZON)
        pdf = self._normal_pdf(wi, m) / (4.0 * np.where(ok, c, 1.0))
        weight = self._fresnel(c) * self._sampling_weight(wi, wo, m)
        ok &= pdf > 0
        return np.where(ok[:, None], wo, 0.0), np.where(ok, weight, 0.0), np.where(ok, pdf, 0.0)
