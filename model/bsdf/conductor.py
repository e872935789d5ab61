"""RoughConductor: microfacet reflection off a rough conductor of complex index n + ik (or F = 1).

Opaque: only pairs with both directions above the surface (+z) scatter."""

from __future__ import annotations

import cmath

import numpy as np

from model.bsdf.constants import COS_HORIZON
from model.bsdf.fresnel import fresnel_amplitudes, fresnel_conductor
from model.bsdf.microfacet import MicrofacetModel, half_vector, identity_muellers, reflect
from model.bsdf.mueller import facet_mueller
from model.bsdf.vectors import dot, unit


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

    def _material_repr(self) -> str:
        return f"eta_complex={self.eta_complex}"

    def _kernel_arguments(self):
        """The shared kernel arguments with the index inserted: (ndf, ax, ay, has_f, n_c,
        masking, sampling), as kernels.conductor and conductor_sample take them."""
        ndf, ax, ay, masking, sampling = self._kernel_parameters()
        n_c = 0j if self.eta_complex is None else self.eta_complex
        return ndf, ax, ay, self.eta_complex is not None, n_c, masking, sampling

    def _kernel(self, wi, wo, want_pdf):
        from model.bsdf.kernels import conductor

        return conductor(wi, wo, *self._kernel_arguments(), want_pdf)

    def _fresnel(self, cos_im):
        if self.eta_complex is None:
            return np.ones_like(cos_im)
        return fresnel_conductor(cos_im, self.eta_complex)

    @staticmethod
    def _over_live_pairs(wi, wo, value):
        """value(wi, wo, half vector) at the pairs with both directions above the horizon,
        0 at the others."""
        live = (wi[..., 2] > COS_HORIZON) & (wo[..., 2] > COS_HORIZON)
        out = np.zeros(wi.shape[:-1])
        if live.any():
            wi, wo = wi[live], wo[live]
            out[live] = value(wi, wo, half_vector(wi, wo))
        return out

    def _eval(self, wi, wo):
        return self._over_live_pairs(wi, wo, lambda wi, wo, m: (
            0.25 * self._fresnel(dot(wi, m)) * self.distribution.D(m)
            * self._g2_over_cosines(wi, wo)))

    def _mueller_kernel(self, wi, wo, f):
        from model.bsdf.mueller_kernel import conductor_muellers

        n_c = 0j if self.eta_complex is None else self.eta_complex
        return conductor_muellers(wi, wo, f, self.eta_complex is not None, n_c)

    def _mueller_shape(self, wi, wo):
        """eval_mueller / eval (n, 4, 4): the facet at the half vector, Fresnel amplitudes of
        n + ik, or of a perfect conductor (r_s = -1, r_p = 1) when eta_complex is None."""
        out = identity_muellers(wi.shape[0])
        live = (wi[:, 2] > COS_HORIZON) & (wo[:, 2] > COS_HORIZON)
        if live.any():
            wi, wo = wi[live], wo[live]
            m = half_vector(wi, wo)
            if self.eta_complex is None:
                r_s, r_p = -np.ones(len(m)), np.ones(len(m))
            else:
                n = self.eta_complex
                r_s, r_p = fresnel_amplitudes(dot(wi, m), n, (n - 1.0) * (n + 1.0))
            out[live] = facet_mueller(wi, wo, m, r_s, r_p)
        return out

    def _pdf(self, wi, wo):
        return self._over_live_pairs(
            wi, wo, lambda wi, wo, m: self._normal_pdf(wi, m) / (4.0 * dot(wo, m)))

    def _sample(self, wi, u):
        if self._compiled_sampling():
            from model.bsdf.kernels import conductor_sample

            return conductor_sample(wi, u, *self._kernel_arguments())
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
