"""Rayleigh-Rice: scatter from a smooth opaque surface (rms height well below the wavelength)
by first-order vector perturbation theory, the `rayleigh-rice` family:

    f(i, o) = 16 pi^2 / lambda^4 cos_i cos_o Q(i, o) S(f),   f = |o_xy + i_xy| / lambda,

S the surface's isotropic K-correlation ("ABC") power spectral density (diffraction's
KCorrelationPSD: rms height, correlation length, exponent), f the spatial frequency the grating
equation picks, Q the polarisation factor of unpolarised light: the mean over the incident
polarisations of the sum over the scattered ones, (Q_ss + Q_sp + Q_ps + Q_pp) / 2, with the
Rayleigh-Rice factors of a medium of dielectric constant eps = (eta + i k)^2 (Church, Jenkinson
and Zavada 1979; Elson and Bennett 1979; J. C. Stover, "Optical Scattering", ch. 5):

    Q_ss = |(eps - 1) cos phi / ((cos_i + q_i)(cos_o + q_o))|^2,        q = sqrt(eps - sin^2)
    Q_sp = |(eps - 1) q_o sin phi / ((cos_i + q_i)(eps cos_o + q_o))|^2
    Q_ps = |(eps - 1) q_i sin phi / ((eps cos_i + q_i)(cos_o + q_o))|^2
    Q_pp = |(eps - 1) (q_i q_o cos phi - eps sin_i sin_o) / ((eps cos_i + q_i)(eps cos_o + q_o))|^2

phi the azimuth of o from the specular plane (0 toward the mirror direction), so that Q is the
Fresnel reflectance R(theta_i) at the mirror direction. The specular beam itself is no part of
f (the families have no delta): its power is R exp(-(4 pi sigma_rel cos_i / lambda)^2),
sigma_rel^2 the part of sigma^2 at propagating frequencies (specular_reflectance).

sample() draws the PSD's own lobe about the mirror direction in direction cosines, truncated
to the unit disk: a uniform azimuth, then the radial distance from the PSD's radial CDF scaled
to the share that reaches the unit circle along that azimuth; pdf() integrates to 1 over the
hemisphere and every weight is 16 pi^2 sigma^2 / lambda^2 cos_i cos_o Q times that share."""

from __future__ import annotations

import math

import numpy as np

from model.bsdf.diffraction import KCorrelationPSD
from model.bsdf.families.base import Parameter, ReflectionFamily, reach_in_unit_disk
from model.bsdf.fresnel import fresnel_conductor

RMS_HEIGHT = Parameter("rms_height_nm", 1e-6, 1e4, True, "rms height of the surface, nm")
CORRELATION_LENGTH = Parameter("correlation_length_um", 1e-4, 1e5, True,
                               "correlation length of the K-correlation PSD (ABC's B), um")
PSD_EXPONENT = Parameter("psd_exponent", 1.01, 10.0, False,
                         "K-correlation exponent c: the PSD falls as f^-(c+1) (ABC's C)")
#: The fixed settings, checked as the parameters are.
WAVELENGTH = Parameter("wavelength_nm", 0.01, 1e6, True, "vacuum wavelength, nm")
ETA = Parameter("eta", 1e-3, 1e3, False, "real part of the surface's refractive index")
K = Parameter("k", 0.0, 1e3, False, "extinction coefficient (imaginary part of the index)")
#: Azimuths of the trapezoid rule of the propagating share (a smooth periodic integrand).
SHARE_AZIMUTHS = 512


def polarisation_factor(eta_complex: complex, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """Rayleigh-Rice Q of unpolarised light, (Q_ss + Q_sp + Q_ps + Q_pp) / 2, for unit
    directions wi, wo (n, 3) above the surface (wi toward the source); symmetric in wi, wo.

    phi is measured from the specular plane: sin_i sin_o cos phi = -wi_xy . wo_xy; where
    either direction is the normal Q does not depend on phi and cos phi = 1 is taken."""
    n = complex(eta_complex)
    eps = n * n
    eps_m1 = (n - 1.0) * (n + 1.0)  # eps - 1 without cancellation for an index near 1
    sin2_i = wi[:, 0] ** 2 + wi[:, 1] ** 2
    sin2_o = wo[:, 0] ** 2 + wo[:, 1] ** 2
    cos_i, cos_o = wi[:, 2], wo[:, 2]
    q_i, q_o = np.sqrt(eps - sin2_i), np.sqrt(eps - sin2_o)  # principal branch, Re >= 0
    sines = np.sqrt(sin2_i * sin2_o)
    live = sines > 0
    cos_phi = np.where(live, -(wi[:, 0] * wo[:, 0] + wi[:, 1] * wo[:, 1])
                       / np.where(live, sines, 1.0), 1.0)
    cos_phi = np.clip(cos_phi, -1.0, 1.0)
    sin2_phi = 1.0 - cos_phi * cos_phi
    s_i, s_o = cos_i + q_i, cos_o + q_o
    p_i, p_o = eps * cos_i + q_i, eps * cos_o + q_o
    ss = cos_phi * cos_phi / np.abs(s_i * s_o) ** 2
    sp = np.abs(q_o) ** 2 * sin2_phi / np.abs(s_i * p_o) ** 2
    ps = np.abs(q_i) ** 2 * sin2_phi / np.abs(p_i * s_o) ** 2
    pp = np.abs(q_i * q_o * cos_phi - eps * sines) ** 2 / np.abs(p_i * p_o) ** 2
    return 0.5 * abs(eps_m1) ** 2 * ((ss + pp) + (sp + ps))


class RayleighRice(ReflectionFamily):
    """Smooth-surface scatter (Rayleigh-Rice, K-correlation PSD) of an opaque dielectric
    (index eta) or conductor (eta + i k) at one wavelength, the `rayleigh-rice` family."""

    family = "rayleigh-rice"
    PARAMETERS = (RMS_HEIGHT, CORRELATION_LENGTH, PSD_EXPONENT)
    SETTINGS = ("wavelength_nm", "eta", "k")

    def __init__(self, rms_height_nm: float = 1.0, correlation_length_um: float = 2.0,
                 psd_exponent: float = 2.0, wavelength_nm: float = 632.8, eta: float = 1.5,
                 k: float = 0.0):
        super().__init__(rms_height_nm=rms_height_nm, correlation_length_um=correlation_length_um,
                         psd_exponent=psd_exponent)
        for setting, value in ((WAVELENGTH, wavelength_nm), (ETA, eta), (K, k)):
            setattr(self, setting.name, setting.check(value))
        self.psd = KCorrelationPSD(self.rms_height_nm * 1e-9, self.correlation_length_um * 1e-6,
                                   self.psd_exponent)
        self.wavelength_m = self.wavelength_nm * 1e-9
        self.eta_complex = complex(self.eta, self.k)
        #: 16 pi^2 sigma^2 / lambda^2: f = scale cos_i cos_o Q psd.lobe(|o_xy + i_xy|, lambda)
        self.scale = (4.0 * math.pi * self.psd.sigma / self.wavelength_m) ** 2

    # --- the model ------------------------------------------------------------------------

    def _eval(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        shift = np.hypot(wo[:, 0] + wi[:, 0], wo[:, 1] + wi[:, 1])
        return (self.scale * wi[:, 2] * wo[:, 2] * polarisation_factor(self.eta_complex, wi, wo)
                * self.psd.lobe(shift, self.wavelength_m))

    def _reachable_share(self, b0: np.ndarray, e: np.ndarray) -> np.ndarray:
        """Share of the PSD lobe about b0 along azimuth e that lies within the unit disk: its
        radial CDF at the distance to the unit circle."""
        return self.psd.radial_cdf(reach_in_unit_disk(b0, e) / self.wavelength_m)

    def _pdf(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        d = wo[:, :2] + wi[:, :2]  # o_xy - b0, b0 = -i_xy the mirror direction's
        r = np.hypot(d[:, 0], d[:, 1])
        e = np.where((r > 0)[:, None], d / np.where(r > 0, r, 1.0)[:, None], [1.0, 0.0])
        share = self._reachable_share(-wi[:, :2], e)
        density = self.psd.lobe(r, self.wavelength_m) * wo[:, 2]
        return np.where(share > 0, density / np.where(share > 0, share, 1.0), 0.0)

    def _sample_directions(self, wi: np.ndarray, u: np.ndarray) -> np.ndarray:
        phi = 2.0 * math.pi * u[:, 1]
        e = np.stack([np.cos(phi), np.sin(phi)], axis=-1)
        b0 = -wi[:, :2]
        reach = reach_in_unit_disk(b0, e)
        share = self.psd.radial_cdf(reach / self.wavelength_m)
        r = np.minimum(self.psd.radial_quantile(u[:, 0] * share) * self.wavelength_m, reach)
        beta = b0 + r[:, None] * e
        z = np.sqrt(np.maximum(1.0 - np.sum(beta * beta, axis=-1), 0.0))
        return np.concatenate([beta, z[:, None]], axis=-1)

    # --- smooth-surface totals --------------------------------------------------------------

    def propagating_share(self, wi) -> np.ndarray:
        """sigma_rel^2 / sigma^2 for incident directions wi (..., 3): the share of the PSD at
        spatial frequencies that leave into real directions (the lobe about the mirror
        direction within the unit disk), by the trapezoid rule over SHARE_AZIMUTHS azimuths."""
        wi = np.asarray(wi, dtype=np.float64)
        wi = wi / np.linalg.norm(wi, axis=-1, keepdims=True)
        phi = 2.0 * math.pi * np.arange(SHARE_AZIMUTHS) / SHARE_AZIMUTHS
        e = np.stack([np.cos(phi), np.sin(phi)], axis=-1)
        return np.mean(self._reachable_share(-wi[..., None, :2], e), axis=-1)

    def fresnel_reflectance(self, wi) -> np.ndarray:
        """R(theta_i) of the flat surface, unpolarised, for incident directions wi (..., 3)."""
        wi = np.asarray(wi, dtype=np.float64)
        return fresnel_conductor(wi[..., 2] / np.linalg.norm(wi, axis=-1), self.eta_complex)

    def _phase_variance(self, wi) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(cos_i > 0, R, (4 pi sigma_rel cos_i / lambda)^2) for incident directions wi."""
        wi = np.asarray(wi, dtype=np.float64)
        cos_i = wi[..., 2] / np.linalg.norm(wi, axis=-1)
        return (cos_i > 0, self.fresnel_reflectance(wi),
                self.scale * cos_i**2 * self.propagating_share(wi))

    def smooth_surface_tis(self, wi) -> np.ndarray:
        """The smooth-surface total integrated scatter R (4 pi sigma_rel cos_i / lambda)^2 for
        incident directions wi (..., 3), which the scatter's hemisphere integral approaches as
        the PSD's lobe narrows (Q cos_o -> R cos_i across it); 0 below the horizon."""
        up, reflectance, x2 = self._phase_variance(wi)
        return np.where(up, reflectance * x2, 0.0)

    def specular_reflectance(self, wi) -> np.ndarray:
        """Power of the specular beam, which f leaves out: R exp(-(4 pi sigma_rel cos_i /
        lambda)^2) for incident directions wi (..., 3); 0 below the horizon."""
        up, reflectance, x2 = self._phase_variance(wi)
        return np.where(up, reflectance * np.exp(-x2), 0.0)
