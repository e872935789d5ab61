"""Rayleigh-Rice's physics by independent routes: its hemisphere integral against the analytic
smooth-surface TIS, the specular beam plus the scatter against the flat surface's reflectance,
the propagating share against TwoScaleDiffraction's relevant fraction, its sampler's density
(integral 1, unbiased weights), the join with the two-scale diffraction model in the smooth
limit, the ABC form of the PSD, and bad settings."""

import math

import mpmath as mp
import numpy as np
import pytest
from bsdf_quadrature import direction
from disk_quadrature import integrate_about_specular
from families_cases import MODELS

from model.bsdf import RayleighRice, RoughConductor, make_family
from model.bsdf.diffraction import TwoScaleDiffraction
from model.bsdf.families.rayleigh_rice import polarisation_factor

GLASS = dict(wavelength_nm=632.8, eta=1.5)
ALUMINIUM = dict(wavelength_nm=632.8, eta=1.37, k=7.6)
THETAS = [0.0, 0.5, 1.0, 1.3]
RR_CASES = sorted(name for name in MODELS if name.startswith("rayleigh-rice"))


def albedo(model, wi) -> float:
    """int f cos_o d omega over the hemisphere, in polar cells about the mirror direction."""
    return integrate_about_specular(lambda wo: model.eval(wi, wo), wi)


@pytest.mark.parametrize("material", [GLASS, ALUMINIUM], ids=["glass", "aluminium"])
@pytest.mark.parametrize(("exponent", "length_um", "tolerance"),
                         [(3.0, 200.0, 3e-3), (3.0, 2000.0, 6e-5), (2.0, 2000.0, 8e-3)])
def test_tis_approaches_the_smooth_surface_tis(material, exponent, length_um, tolerance):
    """As the PSD's lobe narrows (correlation length >> wavelength), the hemisphere integral of
    f cos_o tends to R (4 pi sigma_rel cos_i / lambda)^2; the rest falls as (lambda / b)^(c-1)
    (docs/bsdf-families.md tabulates it)."""
    model = RayleighRice(1.0, length_um, exponent, **material)
    for theta_i in THETAS:
        wi = direction(theta_i, 0.3)
        assert albedo(model, wi) == pytest.approx(float(model.smooth_surface_tis(wi)),
                                                  rel=tolerance)


@pytest.mark.parametrize("material", [GLASS, ALUMINIUM], ids=["glass", "aluminium"])
def test_specular_beam_plus_scatter_is_the_flat_reflectance(material):
    """Energy: R exp(-x^2) + TIS = R (1 - x^2 + x^2) to O(x^4), x = 4 pi sigma_rel cos_i /
    lambda (about 1e-3 here), for a lobe narrow enough that TIS = R x^2."""
    model = RayleighRice(2.0, 2000.0, 3.0, **material)
    for theta_i in THETAS:
        wi = direction(theta_i, 0.3)
        total = float(model.specular_reflectance(wi)) + albedo(model, wi)
        assert total == pytest.approx(float(model.fresnel_reflectance(wi)), rel=2e-6)


@pytest.mark.parametrize("length_um", [0.2, 2.0, 20.0])
@pytest.mark.parametrize("theta_i", [0.0, 0.6, 1.2, 1.5])
def test_propagating_share_against_mpmath_and_the_two_scale_relevant_fraction(length_um,
                                                                              theta_i):
    """sigma_rel^2 / sigma^2 = (1 / 2 pi) int cdf(reach(phi) / lambda) dphi, reach the distance
    from sin theta_i to the unit circle along phi: against mpmath's quadrature (1e-12), and
    against diffraction's iso-circle integral of the same share (TwoScaleDiffraction.
    relevant_fraction, whose 48-node rule errs by up to 5e-5 near grazing)."""
    model = RayleighRice(1.0, length_um, 2.5, **GLASS)
    lam, b, c, r0 = mp.mpf(632.8e-9), mp.mpf(length_um) * mp.mpf("1e-6"), mp.mpf(2.5), \
        mp.sin(theta_i)

    def share(phi):
        along = r0 * mp.cos(phi)
        reach = -along + mp.sqrt(along**2 + 1 - r0**2)
        return 1 - (1 + (b * reach / lam) ** 2) ** (-(c - 1) / 2)

    want = mp.quad(share, mp.linspace(0, 2 * mp.pi, 41)) / (2 * mp.pi)
    got = float(model.propagating_share(direction(theta_i, 0.3)))
    assert got == pytest.approx(float(want), rel=1e-12)
    two_scale = TwoScaleDiffraction(RoughConductor("beckmann", 1e-3, 1.5), model.psd)
    fraction = two_scale.relevant_fraction(np.array(math.sin(theta_i)), model.wavelength_m)
    assert got == pytest.approx(float(fraction), rel=1e-4)


@pytest.mark.parametrize("name", RR_CASES)
@pytest.mark.parametrize("theta_i", [0.0, 0.6, 1.35, 1.5])
def test_pdf_integrates_to_one_and_every_sample_is_valid(name, theta_i):
    model, wi = MODELS[name], direction(theta_i, 0.4)
    mass = integrate_about_specular(lambda wo: model.pdf(wi, wo) / wo[..., 2], wi, azimuths=512)
    assert mass == pytest.approx(1.0, abs=1e-6)
    _, _, pdf = model.sample(wi, np.random.default_rng(2).random((20_000, 3)))
    assert np.all(pdf > 0)


@pytest.mark.parametrize("name", RR_CASES)
@pytest.mark.parametrize("theta_i", [0.0, 1.0])
def test_mean_sample_weight_is_the_albedo(name, theta_i):
    """Stratified sums of sample() weights (256^2 strata) against the hemisphere quadrature."""
    model, wi = MODELS[name], direction(theta_i, 0.4)
    e = (np.arange(256) + 0.5) / 256
    u1, u2 = np.meshgrid(e, e, indexing="ij")
    u = np.stack([u1.ravel(), u2.ravel(), np.full(u1.size, 0.5)], -1)
    assert model.sample(wi, u)[1].mean() == pytest.approx(albedo(model, wi), rel=2e-3)


@pytest.mark.parametrize("material", [GLASS, ALUMINIUM], ids=["glass", "aluminium"])
@pytest.mark.parametrize("theta_i", [0.0, 0.5, 1.0])
def test_joins_the_two_scale_diffraction_model_in_the_smooth_limit(material, theta_i):
    """TwoScaleDiffraction over a nearly flat facet (Beckmann alpha 1e-3) with the same PSD:
    away from the microfacet lobe its diffracted light is R(theta_i) (1 - A) / P times the
    PSD lobe, which for sigma << lambda is 16 pi^2 cos_i^2 R S / lambda^4, so

        f_two_scale / f_rayleigh_rice = cos_i R(theta_i) / (cos_o Q(i, o)) * (1 - A) / x^2,

    x^2 = (4 pi sigma cos_i / lambda)^2 P, A = exp(-x^2): within 2e-3 (the two-scale model's
    256-point lobe integral) from 0.01 to 0.6 in direction cosines off the mirror direction,
    in and across the plane of incidence. At the mirror direction Q cos_o = R cos_i: the two
    agree there, and at normal incidence within 0.3 % (glass) and 2 % (aluminium) out to 0.6."""
    model = RayleighRice(1.0, 2.0, 2.0, **material)
    two_scale = TwoScaleDiffraction(RoughConductor("beckmann", 1e-3, model.eta_complex),
                                    model.psd)
    wi = direction(theta_i, 0.0)
    offsets = np.array([0.01, 0.03, 0.1, 0.3, 0.6])
    for azimuth in (0.0, math.pi / 2, math.pi):
        beta = -wi[:2] + offsets[:, None] * [math.cos(azimuth), math.sin(azimuth)]
        beta = beta[np.sum(beta**2, -1) < 1]
        wo = np.concatenate([beta, np.sqrt(1 - np.sum(beta**2, -1))[:, None]], -1)
        x2 = model.scale * wi[2] ** 2 * model.propagating_share(wi)
        q = polarisation_factor(model.eta_complex, np.broadcast_to(wi, wo.shape), wo)
        ratio = (wi[2] * model.fresnel_reflectance(wi) / (wo[:, 2] * q)
                 * -math.expm1(-x2) / x2)
        got = two_scale.eval(wi, wo, model.wavelength_m) / model.eval(wi, wo)
        np.testing.assert_allclose(got, ratio, rtol=2e-3)
        if theta_i == 0.0:
            bound = 3e-3 if material is GLASS else 2e-2
            np.testing.assert_allclose(got, 1.0, rtol=bound)


def test_the_psd_is_diffractions_k_correlation_and_its_abc_form():
    model = RayleighRice(1.5, 3.0, 2.2, **GLASS)
    assert (model.psd.sigma, model.psd.b, model.psd.c) == pytest.approx((1.5e-9, 3e-6, 2.2))
    a, b, c = model.psd.abc()
    f = np.array([0.0, 1e5, 1e6, 1e7])
    np.testing.assert_allclose(model.psd(f), a / (1 + (b * f) ** 2) ** ((c + 1) / 2),
                               rtol=1e-14)


def test_bad_parameters_and_settings_are_one_clear_error():
    with pytest.raises(ValueError, match=r"rms_height_nm must be finite and in"):
        RayleighRice(-1.0)
    with pytest.raises(ValueError, match=r"psd_exponent must be finite and in \[1.01, 10.0\]"):
        RayleighRice(1.0, 2.0, 1.0)
    with pytest.raises(ValueError, match="correlation_length_um must be a number"):
        RayleighRice(1.0, "long")
    with pytest.raises(ValueError, match="wavelength_nm must be finite and in"):
        RayleighRice(wavelength_nm=0.0)
    with pytest.raises(ValueError, match="eta must be finite and in"):
        RayleighRice(eta=float("nan"))
    with pytest.raises(ValueError, match="k must be finite and in"):
        RayleighRice(k=-0.5)
    with pytest.raises(ValueError, match=r"takes settings \['wavelength_nm', 'eta', 'k'\]"):
        make_family("rayleigh-rice", {"rms_height_nm": 1.0, "correlation_length_um": 2.0,
                                      "psd_exponent": 2.0}, wavelength=633.0)
