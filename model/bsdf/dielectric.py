"""RoughDielectric: Walter et al. 2007 rough dielectric interface, reflection and transmission.

Light may arrive from either side. Internally each pair is mirrored so that wi is on the upper
side, with relative index e = eta_o / eta_i (eta or 1/eta) and e - 1 kept exact, so an
index-matched interface (eta = 1 +- 1e-12) keeps full accuracy. Transmission is Walter's eq. 21
(radiance BTDF, with the eta_o^2 factor)."""

from __future__ import annotations

import math

import numpy as np

from model.bsdf.constants import COS_HORIZON
from model.bsdf.fresnel import (
    dielectric_transmittance,
    fresnel_amplitudes,
    reflectance_transmittance_toward,
)
from model.bsdf.microfacet import MicrofacetModel, half_vector, identity_muellers, reflect
from model.bsdf.mueller import facet_mueller
from model.bsdf.vectors import dot, unit

LOBES = ("reflection", "transmission")


class RoughDielectric(MicrofacetModel):
    """Rough dielectric interface, eta = n_interior / n_exterior, +z on the exterior side.

    lobes restricts the model to one lobe: the other is then neither evaluated nor sampled.
    backend: None picks the compiled kernel when numba is installed (Beckmann, GGX), 'numpy'
    forces the reference path.
    At eta == 1 exactly the transmission is a Dirac delta along -wi: eval and pdf give 0 for
    it, sample() returns wo = -wi with its finite weight and pdf = inf.
    """

    def __init__(
        self,
        distribution: str = "ggx",
        alpha=0.394,
        eta: float = 1.51,
        masking: str = "separable",
        sampling: str | None = None,
        lobes: tuple[str, ...] = LOBES,
        multiple_scattering: bool = False,
        backend: str | None = None,
    ):
        if not (isinstance(eta, (int, float)) and math.isfinite(eta) and eta > 0):
            raise ValueError(f"eta must be a finite number > 0, got {eta!r}")
        lobes = tuple(lobes)
        if not lobes or any(lobe not in LOBES for lobe in lobes) or len(set(lobes)) != len(lobes):
            raise ValueError(f"lobes must be a non-empty subset of {LOBES}, got {lobes!r}")
        self.eta = float(eta)
        self.lobes = lobes
        self.reflection = "reflection" in lobes
        self.transmission = "transmission" in lobes
        super().__init__(distribution, alpha, masking, sampling, multiple_scattering, backend)

    def _material_repr(self) -> str:
        return f"eta={self.eta}"

    def _lobes_repr(self) -> str:
        return f", lobes={self.lobes}"

    def _kernel_arguments(self):
        """(ndf, ax, ay, eta, masking, lobes on, sampling), as kernels.dielectric and
        dielectric_sample take them."""
        ndf, ax, ay, masking, sampling = self._kernel_parameters()
        return ndf, ax, ay, self.eta, masking, self.reflection, self.transmission, sampling

    def _kernel(self, wi, wo, want_pdf):
        from model.bsdf.kernels import dielectric

        return dielectric(wi, wo, *self._kernel_arguments(), want_pdf)

    # --- frame: wi on the upper side ---------------------------------------------------------

    def _mirror(self, wi, wo):
        """Mirror pairs with wi below the surface; return wi, wo, e, e - 1 and the z signs."""
        sign = np.where(wi[..., 2] < 0, -1.0, 1.0)
        flip = np.stack([np.ones_like(sign), np.ones_like(sign), sign], axis=-1)
        eta = self.eta
        e = np.where(sign < 0, 1.0 / eta, eta)
        em1 = np.where(sign < 0, (1.0 - eta) / eta, eta - 1.0)
        return wi * flip, None if wo is None else wo * flip, e, em1, flip

    def _lobe_masks(self, wi, wo):
        ci = wi[..., 2]
        co = wo[..., 2]
        live = (ci > COS_HORIZON) & (np.abs(co) > COS_HORIZON)
        return live & (co > 0) & self.reflection, live & (co < 0) & self.transmission

    def _transmission_normal(self, wi, wo, em1):
        """Walter's transmission half vector m (m.z > 0), |wi + e wo|^2, and whether valid."""
        v = (wi + wo) + em1[..., None] * wo
        n2 = dot(v, v)
        m = v * (-1.0 / np.sqrt(np.where(n2 > 0, n2, 1.0)))[..., None]
        m = m * np.where(m[..., 2] < 0, -1.0, 1.0)[..., None]
        valid = (n2 > 0) & (m[..., 2] > 0) & (dot(wi, m) > 0) & (dot(wo, m) < 0)
        return m, n2, valid

    # --- eval -------------------------------------------------------------------------------

    def _eval(self, wi, wo):
        wi, wo, e, em1, _ = self._mirror(wi, wo)
        refl, trans = self._lobe_masks(wi, wo)
        f = np.zeros(wi.shape[:-1])
        if refl.any():
            f[refl] = self._eval_reflection(wi[refl], wo[refl], e[refl], em1[refl])
        if trans.any():
            f[trans] = self._eval_transmission(wi[trans], wo[trans], e[trans], em1[trans])
        return f

    def _eval_reflection(self, wi, wo, e, em1):
        m = half_vector(wi, wo)
        fr, _ = reflectance_transmittance_toward(dot(wi, m), e, em1)
        return 0.25 * fr * self.distribution.D(m) * self._g2_over_cosines(wi, wo)

    def _eval_transmission(self, wi, wo, e, em1):
        m, n2, valid = self._transmission_normal(wi, wo, em1)
        im, om = dot(wi, m), -dot(wo, m)
        ft = dielectric_transmittance(im, om, e)
        val = (im * om * e * e * ft * self.distribution.D(m)
               * self._g2_over_cosines(wi, wo) / np.where(valid, n2, 1.0))
        return np.where(valid, val, 0.0)

    # --- Mueller ----------------------------------------------------------------------------

    def _mueller_kernel(self, wi, wo, f):
        from model.bsdf.mueller_kernel import dielectric_muellers

        return dielectric_muellers(wi, wo, f, self.eta, self.reflection, self.transmission)

    def _mueller_shape(self, wi, wo):
        """eval_mueller / eval (n, 4, 4): one facet, at the reflection half vector with the
        complex Fresnel amplitudes (total internal reflection keeps its phase), or at
        Walter's transmission normal with the transmitted amplitudes, whose ratio
        t_p / t_s = (c + e cos_t) e / (e^2 c + e cos_t) is all the normalised matrix needs."""
        wi_up, wo_up, e, em1, flip = self._mirror(wi, wo)
        refl, trans = self._lobe_masks(wi_up, wo_up)
        out = identity_muellers(wi.shape[0])
        if refl.any():
            wi_r, wo_r, e_r = wi[refl], wo[refl], e[refl]
            m = half_vector(wi_r, wo_r)
            r_s, r_p = fresnel_amplitudes(dot(wi_r, m), e_r, em1[refl] * (e_r + 1.0))
            out[refl] = facet_mueller(wi_r, wo_r, m, r_s, r_p)
        if trans.any():
            m, _, valid = self._transmission_normal(wi_up[trans], wo_up[trans], em1[trans])
            e_t = e[trans]
            c, e_ct = dot(wi_up[trans], m), -e_t * dot(wo_up[trans], m)
            den_s = np.where(valid, c + e_ct, 1.0)
            den_p = np.where(valid, e_t * e_t * c + e_ct, 1.0)
            out[trans] = facet_mueller(wi[trans], wo[trans], m * flip[trans], 1.0 / den_s,
                                       e_t / den_p)
        return out

    # --- pdf --------------------------------------------------------------------------------

    def _pdf(self, wi, wo):
        wi, wo, e, em1, _ = self._mirror(wi, wo)
        refl, trans = self._lobe_masks(wi, wo)
        p = np.zeros(wi.shape[:-1])
        if refl.any():
            wi_r, wo_r = wi[refl], wo[refl]
            m = half_vector(wi_r, wo_r)
            choice = (reflectance_transmittance_toward(dot(wi_r, m), e[refl], em1[refl])[0]
                      if self.transmission else 1.0)
            p[refl] = choice * self._normal_pdf(wi_r, m) / (4.0 * dot(wo_r, m))
        if trans.any():
            wi_t, wo_t, e_t = wi[trans], wo[trans], e[trans]
            m, n2, valid = self._transmission_normal(wi_t, wo_t, em1[trans])
            om = -dot(wo_t, m)
            choice = (dielectric_transmittance(dot(wi_t, m), om, e_t)
                      if self.reflection else 1.0)
            val = (choice * self._normal_pdf(wi_t, m) * e_t * e_t * om
                   / np.where(valid, n2, 1.0))
            p[trans] = np.where(valid, val, 0.0)
        return p

    # --- sample -----------------------------------------------------------------------------

    def _sample(self, wi, u):
        if self._compiled_sampling():
            from model.bsdf.kernels import dielectric_sample

            return dielectric_sample(wi, u, *self._kernel_arguments())
        wi, _, e, em1, flip = self._mirror(unit(wi), None)
        m = self._sample_normal(wi, u[:, 0], u[:, 1])
        c = dot(wi, m)
        fr, ft = reflectance_transmittance_toward(np.abs(c), e, em1)
        if self.reflection and self.transmission:
            reflected = u[:, 2] < fr
        else:
            reflected = np.full(c.shape, self.reflection)
        # refraction with e - 1 kept exact: wo = -wi / e + (c - e cos_t) / e m, where
        # c - e cos_t = (1 - e^2) / (c + e cos_t)
        e_ct = np.sqrt(np.maximum(em1 * (e + 1.0) + c * c, 0.0))  # as in fresnel
        gap = -em1 * (e + 1.0) / np.where(c + e_ct > 0, c + e_ct, 1.0)  # c - e cos_t
        wo_t = (-wi + gap[:, None] * m) / e[:, None]
        wo = np.where(reflected[:, None], reflect(wi, m), wo_t)
        lobe_p = np.where(reflected, fr, ft) if self.reflection and self.transmission else 1.0
        lobe_f = 1.0 if self.reflection and self.transmission else np.where(reflected, fr, ft)
        co = wo[:, 2]
        ok = (c > 0) & (m[:, 2] > 0) & (wi[:, 2] > COS_HORIZON) & (np.abs(co) > COS_HORIZON)
        ok &= np.where(reflected, co > 0, (co < 0) & (ft > 0))
        jac = np.where(reflected, 1.0 / (4.0 * np.abs(c)),
                       e * e_ct / np.where(gap != 0, gap * gap, 1.0))  # e^2 |o.m| / (i.m + e o.m)^2
        pdf = lobe_p * self._normal_pdf(wi, m) * jac
        pdf = np.where(~reflected & (gap == 0), np.inf, pdf)  # eta == 1: Dirac transmission
        weight = lobe_f * self._sampling_weight(wi, wo, m)
        ok &= pdf > 0
        return (np.where(ok[:, None], wo * flip, 0.0), np.where(ok, weight, 0.0),
                np.where(ok, pdf, 0.0))
