"""Two-scale reflection + diffraction: PSD, relevant roughness, limits, energy, wavelength."""

import numpy as np
import pytest

from model.bsdf import RoughConductor, RoughDielectric
from model.bsdf.diffraction import (
    KCorrelationPSD,
    TwoScaleDiffraction,
    diffraction_fraction,
    harvey_shack_specular,
    needs_diffraction,
)

LAMBDA = 633e-9


def direction(theta_deg, phi_deg=0.0):
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])


OUT = np.array([direction(t, 180) for t in (0, 10, 20, 30, 40, 60, 80)] + [direction(40, 90)])


@pytest.mark.parametrize("c", [1.5, 2.0, 3.5])
def test_psd_integrates_to_the_height_variance_and_its_quantile_inverts_its_cdf(c):
    psd = KCorrelationPSD(20e-9, 2e-6, c)
    t = np.linspace(0.0, 1.0 - 1e-9, 400001)  # f = b^-1 tan-like map keeps the tail
    f = np.tan(t * np.pi / 2) / psd.b
    integrand = 2 * np.pi * psd(f) * f * np.gradient(f, t)
    assert np.trapezoid(integrand, t) == pytest.approx(psd.sigma**2, rel=2e-3)
    u = np.linspace(0.0, 0.999, 50)
    assert np.allclose(psd.radial_cdf(psd.radial_quantile(u)), u, atol=1e-12)


@pytest.mark.parametrize("r0", [0.0, 0.3, 0.7, 0.95])
def test_relevant_fraction_is_the_lobe_share_inside_the_unit_disk(r0):
    """Brute force: the lobe k integrated on a fine grid over the unit disk of direction cosines."""
    model = TwoScaleDiffraction(RoughConductor("ggx", 0.2), KCorrelationPSD(30e-9, 1.5e-6, 2.0))
    n = 1201
    x = np.linspace(-1, 1, n)
    xx, yy = np.meshgrid(x, x, indexing="ij")
    inside = xx**2 + yy**2 < 1
    k = model.psd.lobe(np.hypot(xx - r0, yy), LAMBDA)
    brute = np.sum(k * inside) * (x[1] - x[0]) ** 2
    assert model.relevant_fraction(np.array(r0), LAMBDA) == pytest.approx(brute, rel=5e-3)


def test_smooth_nano_surface_gives_the_microfacet_model():
    mf = RoughConductor("ggx", 0.2, None, masking="correlated")
    for sigma, tol in ((1e-10, 1e-5), (1e-11, 1e-7)):
        model = TwoScaleDiffraction(mf, KCorrelationPSD(sigma, 1e-6, 2.0))
        f = model.eval(np.broadcast_to(direction(30), OUT.shape), OUT, LAMBDA)
        assert np.allclose(f, mf.eval(direction(30), OUT), rtol=tol)


@pytest.mark.parametrize("mf", [RoughConductor("ggx", 0.2, 0.2 + 3j, masking="correlated"),
                                RoughDielectric("beckmann", 0.15, 1.5)])
def test_geometric_optics_limit_large_features_give_the_microfacet_model(mf):
    """Correlation length / wavelength -> infinity at fixed sigma / lambda: the diffraction lobe
    shrinks onto each facet's mirror direction and the sum returns the microfacet model."""
    wi = np.broadcast_to(direction(30), OUT.shape)
    g = mf.eval(direction(30), OUT)
    sig = g > 1e-3 * g.max()
    errors = []
    for b in (1e-5, 1e-3, 1e-1):
        model = TwoScaleDiffraction(mf, KCorrelationPSD(60e-9, b, 3.0))
        f = model.eval(wi, OUT, LAMBDA)
        errors.append(np.max(np.abs(f[sig] / g[sig] - 1)))
    assert errors[0] > 0.02  # diffraction is visible at b = 16 wavelengths
    assert errors[2] < 1e-4 and errors[1] < 1e-2 and errors[2] < errors[1] < errors[0]


@pytest.mark.parametrize("sigma,b", [(50e-9, 1e-6), (100e-9, 0.5e-6), (30e-9, 5e-6)])
@pytest.mark.parametrize("theta", [0.0, 60.0])
def test_energy_is_that_of_the_microfacet_model_and_within_one(sigma, b, theta):
    mf = RoughConductor("ggx", 0.3, None, masking="correlated")
    model = TwoScaleDiffraction(mf, KCorrelationPSD(sigma, b, 2.0), samples=64)
    rng = np.random.default_rng(3)
    n = 4000
    u = rng.random((n, 2))
    z = np.sqrt(u[:, 0])
    r = np.sqrt(1 - z * z)
    wo = np.stack([r * np.cos(2 * np.pi * u[:, 1]), r * np.sin(2 * np.pi * u[:, 1]), z], -1)
    wi = np.broadcast_to(direction(theta), wo.shape)
    f = model.eval(wi, wo, LAMBDA) * np.pi  # cosine-weighted proposal: f cos / pdf = pi f
    g = mf.eval(wi, wo) * np.pi
    diff = f - g
    assert abs(diff.mean()) < 4.5 * diff.std() / np.sqrt(n)
    assert f.mean() < 1 + 4.5 * f.std() / np.sqrt(n)
    assert np.all(f >= 0)


def test_shorter_wavelengths_diffract_more():
    mf = RoughConductor("ggx", 0.1, None, masking="correlated")
    model = TwoScaleDiffraction(mf, KCorrelationPSD(40e-9, 3e-6, 2.0))
    wi, wo = direction(20), direction(20, 180)
    peak = mf.eval(wi, wo)
    values = [model.eval(wi, wo, lam) for lam in (400e-9, 633e-9, 1550e-9, 10.6e-6)]
    assert values[0] < values[1] < values[2] < values[3] < 1.0001 * peak
    a, share = model.specular_fraction(wi, wo, 633e-9)
    assert 0 < share < 1 and a == pytest.approx(
        harvey_shack_specular(40e-9 * np.sqrt(share), 633e-9, np.dot(wi, (wi + wo) / 2)
                              / np.linalg.norm((wi + wo) / 2)))


def test_transmission_diffracts_too_and_a_conductor_keeps_its_empty_lower_side():
    """The transmitted lobe is diffracted as well (tests/bsdf/test_bsdf_diffraction_transmission.py
    checks it); a conductor has nothing below the surface to diffract."""
    mf = RoughDielectric("ggx", 0.3, 1.5)
    model = TwoScaleDiffraction(mf, KCorrelationPSD(80e-9, 1e-6, 2.0))
    wi, wo = direction(20), direction(167, 180)
    assert model.eval(wi, wo, LAMBDA) < 0.95 * mf.eval(wi, wo)
    metal = TwoScaleDiffraction(RoughConductor("ggx", 0.3), KCorrelationPSD(80e-9, 1e-6, 2.0))
    assert metal.eval(wi, wo, LAMBDA) == 0.0


def test_diffraction_fraction_and_decision():
    assert diffraction_fraction(0.0, LAMBDA, 0.0) == 0.0
    assert diffraction_fraction(1e-9, LAMBDA, 0.0) == pytest.approx(
        (4 * np.pi * 1e-9 / LAMBDA) ** 2, rel=1e-3)
    assert diffraction_fraction(1e-6, LAMBDA, 0.0) == pytest.approx(1.0)
    assert diffraction_fraction(20e-9, LAMBDA, np.radians(80)) < diffraction_fraction(
        20e-9, LAMBDA, 0.0)
    assert needs_diffraction(20e-9, LAMBDA, 0.0) and not needs_diffraction(0.1e-9, LAMBDA, 0.0)


def test_bad_inputs_are_one_clear_error():
    with pytest.raises(ValueError, match="rms_height_m"):
        KCorrelationPSD(-1e-9, 1e-6)
    with pytest.raises(ValueError, match="exponent"):
        KCorrelationPSD(1e-9, 1e-6, 1.0)
    psd = KCorrelationPSD(1e-9, 1e-6)
    with pytest.raises(ValueError, match="samples"):
        TwoScaleDiffraction(RoughConductor("ggx", 0.2), psd, samples=3)
    with pytest.raises(ValueError, match="wavelength_m"):
        TwoScaleDiffraction(RoughConductor("ggx", 0.2), psd).eval(direction(0), direction(5), 0.0)
    with pytest.raises(ValueError, match="wavelength_m"):
        diffraction_fraction(1e-9, -1.0, 0.0)
