"""Two-scale reflection + diffraction (Holzschuch and Pacanowski 2017) over a microfacet model,
extended to the transmitted lobe of a dielectric by the same scalar (Harvey-Shack) theory.

The surface has two scales: micro-geometry much larger than the wavelength (the microfacet
model: D, G, F) and nano-geometry of rms height sigma_s with a K-correlation power spectral
density S(f) = sigma_s^2 b^2 (c - 1) / (2 pi) (1 + b^2 f^2)^(-(c+1)/2). Light leaving a facet
from medium n_i into medium n_o (n_o = n_i for reflection) keeps the specular fraction
A = exp(-(2 pi sigma_rel |n_i wi + n_o wo| / lambda)^2) (lambda in vacuum; |wi + wo| = 2 cos theta_d
for reflection in air, the Harvey-Shack factor; n_o cos theta_t - n_i cos theta_i for
transmission); sigma_rel is the part of sigma_s whose spatial frequencies leave into real
directions. The rest, 1 - A, is diffracted: the grating equation n_o (o_xy - o'_xy) = lambda f
puts it in the lobe S(f) / sigma_rel^2 about the specular direction o' of each facet, i.e. in
direction cosines of the exit medium with the wavelength lambda / n_o. Convolving that lobe
with the microfacet lobe gives

    f(i, o) = A(o) f_mf(o) + integral k(o_xy - o'_xy) (1 - A(o')) / P(o') f_mf(o') d^2 o'_xy,

k the lobe per unit area of direction cosines, P(o') its share inside the unit disk
(sigma_rel^2 / sigma_s^2). Since f |cos o| d omega = f d^2 o_xy on either side (Walter's
transmission BSDF integrates to the transmitted flux this way), the second term carries exactly
(1 - A) of the microfacet energy of its side: R and T are those of the microfacet model. The
integral uses a fixed scrambled Sobol set, half drawn from k and half from the microfacet
sampler of the lobe evaluated, combined by the balance heuristic. See docs/diffraction.md.
"""

from __future__ import annotations

import copy

import numpy as np
from scipy.stats import qmc

from model.bsdf.vectors import directions

#: Gauss-Legendre nodes of the relevant-fraction integral P(o') (a smooth 1D integral).
FRACTION_NODES = 48
#: P(o') is tabulated against |o'_xy| on this many points per evaluation, then interpolated.
FRACTION_TABLE = 257
#: Direction pairs whose lobe integrals are evaluated together (each pair holds `samples`
#: points in every array): bounds the memory of a fit's aperture average of a narrow lobe.
PAIRS_PER_BLOCK = 8192


class KCorrelationPSD:
    """Isotropic K-correlation ("ABC") surface PSD with rms height, correlation length, exponent c.

    S(f) = sigma^2 b^2 (c - 1) / (2 pi) (1 + b^2 f^2)^(-(c+1)/2), in m^4 with f in 1/m; it
    integrates to sigma^2 over the frequency plane (c > 1). c = 2 is an exponential correlation.
    """

    def __init__(self, rms_height_m: float, correlation_length_m: float, exponent: float = 2.0):
        for name, value in (("rms_height_m", rms_height_m),
                            ("correlation_length_m", correlation_length_m)):
            if not (np.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be positive and finite, got {value!r}")
        if not (np.isfinite(exponent) and exponent > 1.0):
            raise ValueError(f"exponent c must be finite and > 1, got {exponent!r}")
        self.sigma = float(rms_height_m)
        self.b = float(correlation_length_m)
        self.c = float(exponent)

    @classmethod
    def from_abc(cls, a: float, b: float, c: float) -> KCorrelationPSD:
        """The PSD written as Church's ABC form A / (1 + (B f)^2)^((C+1)/2) (A in m^4, B in m):
        B is the correlation length, C the exponent and sigma^2 = 2 pi A / (B^2 (C - 1))."""
        if not (np.isfinite(a) and a > 0.0):
            raise ValueError(f"A must be positive and finite, got {a!r}")
        if not (np.isfinite(b) and b > 0.0 and np.isfinite(c) and c > 1.0):
            raise ValueError(f"B must be positive and C > 1 (both finite), got B={b!r}, C={c!r}")
        return cls(float(np.sqrt(2.0 * np.pi * a / (b * b * (c - 1.0)))), b, c)

    def abc(self) -> tuple[float, float, float]:
        """(A, B, C) of the ABC form A / (1 + (B f)^2)^((C+1)/2): A in m^4, B in m."""
        return self.sigma**2 * self.b**2 * (self.c - 1.0) / (2.0 * np.pi), self.b, self.c

    def __call__(self, f: np.ndarray) -> np.ndarray:
        """S(|f|) in m^4."""
        f = np.asarray(f, dtype=np.float64)
        norm = self.sigma**2 * self.b**2 * (self.c - 1.0) / (2.0 * np.pi)
        return norm * (1.0 + (self.b * f) ** 2) ** (-0.5 * (self.c + 1.0))

    def lobe(self, s: np.ndarray, wavelength_m) -> np.ndarray:
        """S(|s| / lambda) / (sigma^2 lambda^2): the PSD as a density over displacements s in
        direction cosines (the grating equation's s = lambda f), integrating to 1 over the plane."""
        return self(np.asarray(s, dtype=np.float64) / wavelength_m) / (
            self.sigma**2 * np.asarray(wavelength_m) ** 2)

    def radial_cdf(self, f: np.ndarray) -> np.ndarray:
        """Share of sigma^2 at spatial frequencies below |f|: 1 - (1 + b^2 f^2)^(-(c-1)/2)."""
        f = np.asarray(f, dtype=np.float64)
        return -np.expm1(-0.5 * (self.c - 1.0) * np.log1p((self.b * f) ** 2))

    def radial_quantile(self, t: np.ndarray) -> np.ndarray:
        """|f| with radial_cdf(|f|) = t, t in [0, 1)."""
        t = np.asarray(t, dtype=np.float64)
        x = np.expm1(-2.0 / (self.c - 1.0) * np.log1p(-t))
        return np.sqrt(np.maximum(x, 0.0)) / self.b


def debye_waller(rms_height_m, wavelength_m, path) -> np.ndarray:
    """Unscattered fraction exp(-(2 pi sigma path / lambda)^2) of a plane wave whose phase moves by
    2 pi path h / lambda per height h (path: optical path per unit height, |n_i wi + n_o wo|)."""
    x = 2.0 * np.pi * np.asarray(rms_height_m) * np.asarray(path) / np.asarray(wavelength_m)
    return np.exp(-(x * x))


def harvey_shack_specular(rms_height_m, wavelength_m, cos_theta) -> np.ndarray:
    """Harvey-Shack specular (unscattered) fraction A = exp(-(4 pi sigma cos theta / lambda)^2)."""
    return debye_waller(rms_height_m, wavelength_m, 2.0 * np.asarray(cos_theta))


def transmitted_path(theta: float, eta: float) -> float:
    """Optical path per unit height eta cos theta_t - cos theta_i of the refracted specular wave
    (theta from the normal in the incident medium, eta = n_o / n_i); 0 under total reflection."""
    sin_t2 = (np.sin(theta) / eta) ** 2
    if sin_t2 >= 1.0:
        return 0.0
    return float(abs(eta * np.sqrt(1.0 - sin_t2) - np.cos(theta)))


def diffraction_fraction(rms_height_m: float, wavelength_m: float, theta: float,
                         eta: float | None = None) -> float:
    """Upper bound of the share of light that diffraction moves out of the microfacet lobe at
    incidence theta (radians), 1 - A with sigma_rel <= sigma and the facet along the macro normal:
    the reflected lobe (eta None), or the transmitted one into relative index eta = n_o / n_i
    (wavelength_m then in the incident medium)."""
    if not (wavelength_m > 0 and rms_height_m >= 0):
        raise ValueError("wavelength_m must be > 0 and rms_height_m >= 0")
    path = 2.0 * np.cos(theta) if eta is None else transmitted_path(theta, eta)
    return float(-np.expm1(-(2.0 * np.pi * rms_height_m * path / wavelength_m) ** 2))


def needs_diffraction(rms_height_m: float, wavelength_m: float, theta: float,
                      threshold: float = 1e-3, eta: float | None = None) -> bool:
    """Whether diffraction can change the lobe's signal by more than `threshold` (relative)."""
    return diffraction_fraction(rms_height_m, wavelength_m, theta, eta) > threshold


class TwoScaleDiffraction:
    """Microfacet model + nano-scale diffraction; eval(wi, wo, wavelength_m) in 1/sr, no cosine.

    model: a single-scattering RoughConductor (reflection above the surface) or RoughDielectric
    (both lobes, lit from either side; interior index model.eta); psd: KCorrelationPSD of the
    nano-geometry; samples: points of the lobe integral per pair.
    """

    def __init__(self, model, psd: KCorrelationPSD, samples: int = 256):
        if int(samples) != samples or samples < 2 or samples % 2:
            raise ValueError(f"samples must be an even integer >= 2, got {samples!r}")
        self.model = model
        self.psd = psd
        self.samples = int(samples)
        self.eta = getattr(model, "eta", None)  # None: a conductor, reflection above only
        self._samplers = {lobe: self._one_lobe(lobe) for lobe in ("reflection", "transmission")}
        self._u = qmc.Sobol(d=3, scramble=True, seed=20170707).random(self.samples)
        x, w = np.polynomial.legendre.leggauss(FRACTION_NODES)
        self._t, self._w = 0.5 * (x + 1.0), 0.5 * w

    # --- pieces -------------------------------------------------------------------------

    def _one_lobe(self, lobe: str):
        """The model restricted to one lobe, to draw the convolution's points from (a dielectric
        with both lobes would send only F of them to the reflected side)."""
        if lobe not in getattr(self.model, "lobes", ()) or len(self.model.lobes) == 1:
            return self.model
        one = copy.copy(self.model)
        one.lobes = (lobe,)
        one.reflection, one.transmission = lobe == "reflection", lobe == "transmission"
        return one

    def _index(self, w: np.ndarray) -> np.ndarray:
        """Refractive index of the medium on w's side (1 above, model.eta below)."""
        return np.where(w[..., 2] > 0.0, 1.0, self.eta if self.eta is not None else 1.0)

    def relevant_fraction(self, r0: np.ndarray, wavelength_m) -> np.ndarray:
        """sigma_rel^2 / sigma_s^2: share of the lobe centred at |o'_xy| = r0 in the unit disk
        (wavelength_m: in the exit medium; broadcasts with r0)."""
        r0 = np.clip(np.asarray(r0, dtype=np.float64), 0.0, 1.0)
        lam = np.asarray(wavelength_m, dtype=np.float64)
        q = self.psd.radial_cdf
        lo = q((1.0 - r0) / lam)
        hi = q((1.0 + r0) / lam)
        t = lo[..., None] + (hi - lo)[..., None] * self._t
        rho = self.psd.radial_quantile(t) * lam[..., None]
        with np.errstate(divide="ignore", invalid="ignore"):
            cos_arc = (rho * rho + r0[..., None] ** 2 - 1.0) / (2.0 * rho * r0[..., None])
        arc = np.arccos(np.clip(np.nan_to_num(cos_arc, nan=-1.0), -1.0, 1.0)) / np.pi
        return lo + (hi - lo) * np.sum(arc * self._w, axis=-1)

    def specular_fraction(self, wi: np.ndarray, wo: np.ndarray, wavelength_m: float,
                          table: tuple[np.ndarray, np.ndarray] | None = None):
        """A(wi, wo) of the facet that reflects or refracts wi into wo, and sigma_rel^2 /
        sigma_s^2 (table: P against |wo_xy| for wo's side, as _lobe builds it)."""
        n_i, n_o = self._index(wi), self._index(wo)
        path = np.linalg.norm(n_i[..., None] * wi + n_o[..., None] * wo, axis=-1)
        r0 = np.hypot(wo[..., 0], wo[..., 1])
        share = (np.interp(r0, *table) if table is not None
                 else self.relevant_fraction(r0, wavelength_m / n_o))
        return debye_waller(self.psd.sigma * np.sqrt(share), wavelength_m, path), share

    def _f_side(self, wi: np.ndarray, w: np.ndarray, side: float) -> np.ndarray:
        """Microfacet f(wi, w) for w on the exit side (sign of w_z = side), 0 elsewhere."""
        ok = w[..., 2] * side > 0.0
        return np.where(ok, self.model.eval(wi, np.where(ok[..., None], w, [0, 0, side])), 0.0)

    # --- public -------------------------------------------------------------------------

    def eval(self, wi, wo, wavelength_m: float) -> np.ndarray:
        """f(wi, wo) in 1/sr (no cosine) at the vacuum wavelength wavelength_m."""
        if not (np.isfinite(wavelength_m) and wavelength_m > 0.0):
            raise ValueError(f"wavelength_m must be positive and finite, got {wavelength_m!r}")
        wi, wo = directions(wi, wo)
        shape = wi.shape[:-1]
        wi, wo = wi.reshape(-1, 3), wo.reshape(-1, 3)
        f = np.asarray(self.model.eval(wi, wo), dtype=np.float64).copy()
        for lit in (1.0, -1.0) if self.eta is not None else (1.0,):
            for side in (1.0, -1.0) if self.eta is not None else (1.0,):
                use = (wi[:, 2] * lit > 0.0) & (wo[:, 2] * side > 0.0)
                lobe = "reflection" if lit == side else "transmission"
                pairs = np.flatnonzero(use)
                for start in range(0, len(pairs), PAIRS_PER_BLOCK):
                    block = pairs[start:start + PAIRS_PER_BLOCK]
                    f[block] = self._lobe(wi[block], wo[block], wavelength_m, side, lobe)
        return f.reshape(shape)

    def _lobe(self, wi, wo, lam0, side, lobe) -> np.ndarray:
        """f at pairs of one lobe whose wo all leave on one side (side = sign of wo_z)."""
        n, half = wi.shape[0], self.samples // 2
        lam = lam0 / float(self._index(np.array([0.0, 0.0, side])))
        grid = np.linspace(0.0, 1.0, FRACTION_TABLE)
        table = (grid, self.relevant_fraction(grid, lam))
        a_o, _ = self.specular_fraction(wi, wo, lam0, table)
        specular = a_o * self._f_side(wi, wo, side)
        u = self._u
        # strategy 1: displacement from the lobe; strategy 2: specular direction from the model
        rho = self.psd.radial_quantile(u[:half, 0]) * lam
        phi = 2.0 * np.pi * u[:half, 1]
        src1_xy = wo[:, None, :2] - np.stack([rho * np.cos(phi), rho * np.sin(phi)], -1)[None]
        r2 = np.sum(src1_xy**2, axis=-1)
        src1 = np.concatenate([src1_xy, side * np.sqrt(np.maximum(0.0, 1.0 - r2))[..., None]], -1)
        wi_rep = np.broadcast_to(wi[:, None, :], (n, half, 3))
        sampler = self._samplers[lobe]
        src2, _, _ = sampler.sample(wi_rep, np.broadcast_to(u[half:], (n, half, 3)))
        ok = np.concatenate([r2 < 1.0, src2[..., 2] * side > 0.0], axis=1)
        src = np.concatenate([src1, np.where(ok[:, half:, None], src2, [0.0, 0.0, side])], axis=1)
        wi_all = np.broadcast_to(wi[:, None, :], src.shape)
        f_src = np.where(ok, self._f_side(wi_all, src, side), 0.0)
        a_src, share = self.specular_fraction(wi_all, src, lam0, table)
        k = self.psd.lobe(np.linalg.norm(wo[:, None, :2] - src[..., :2], axis=-1), lam)
        p_model = (np.where(ok, sampler.pdf(wi_all, src), 0.0)
                   / np.maximum(np.abs(src[..., 2]), 1e-300))
        mixture = 0.5 * (k + p_model)
        with np.errstate(divide="ignore", invalid="ignore"):
            terms = np.where(ok & (mixture > 0.0) & (share > 0.0),
                             k * (1.0 - a_src) / share * f_src / mixture, 0.0)
        return specular + terms.mean(axis=1)
