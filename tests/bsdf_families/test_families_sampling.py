"""Every family's sampler against its density: chi-square of sample() over a binned sphere
against pdf(), the fraction of valid samples against the pdf's integral, and weight = f cos / pdf
and pdf = pdf() for every returned sample."""

import mpmath as mp
import numpy as np
import pytest
from bsdf_quadrature import chi_square_pvalue, direction
from families_cases import MODELS

from model.bsdf import ABg

N = 60_000
P_MIN = 1e-3  # per test; about 30 tests at fixed seeds


@pytest.mark.parametrize("theta_i", [0.0, 0.6, 1.35])
@pytest.mark.parametrize("name", sorted(MODELS))
def test_samples_follow_the_pdf(name, theta_i):
    model = MODELS[name]
    wi = direction(theta_i, 0.4)
    u = np.random.default_rng(17).random((N, 3))
    wo, weight, pdf = model.sample(wi, u)
    ok = pdf > 0
    p_value, mass = chi_square_pvalue(wo[ok], lambda d: model.pdf(wi, d), nz=16, nphi=32,
                                      order=12)
    assert p_value > P_MIN
    frac = ok.mean()
    # ABg's and Rayleigh-Rice's peaks are finer than the cells (at grazing incidence a sliver
    # above the horizon): test_abg_valid_fraction, test_rayleigh_rice's pdf integral
    if not name.startswith(("abg", "rayleigh-rice")):
        assert abs(frac - mass) < 5 * np.sqrt(max(frac * (1 - frac), 1e-4) / N) + 2e-3
    np.testing.assert_allclose(pdf[ok], model.pdf(wi, wo[ok]), rtol=1e-12)
    f = model.eval(wi, wo[ok])
    np.testing.assert_allclose(weight[ok], f * wo[ok, 2] / pdf[ok], rtol=1e-12)


@pytest.mark.parametrize("name", sorted(MODELS))
def test_incidence_below_the_surface_gives_failed_samples(name):
    wo, weight, pdf = MODELS[name].sample(direction(2.0), np.full((4, 3), 0.3))
    assert not wo.any() and not weight.any() and not pdf.any()


def test_lambert_weights_are_its_albedo():
    model = MODELS["lambert"]
    _, weight, _ = model.sample(direction(0.9), np.random.default_rng(1).random((1000, 3)))
    np.testing.assert_allclose(weight, model.rho, rtol=1e-14)


@pytest.mark.parametrize("abg", [(2e-3, 1e-3, 2.0), (0.05, 0.02, 1.5), (0.2, 0.0, 0.0),
                                 (0.01, 0.5, -1.0)])
def test_abg_valid_fraction_at_normal_incidence_is_the_disks_share(abg):
    """The sampler spreads |x| over [0, 2]; at normal incidence the valid share is the mass
    within |x| < 1, int_0^1 r / (B + r^g) dr / int_0^2 (mpmath quadrature)."""
    a, b, g = abg
    radial = lambda r: r / (b + r**g)  # noqa: E731
    share = float(mp.quad(radial, [0, 0.01, 0.1, 1]) / mp.quad(radial, [0, 0.01, 0.1, 1, 2]))
    _, _, pdf = ABg(*abg).sample(direction(0.0), np.random.default_rng(3).random((N, 3)))
    frac = (pdf > 0).mean()
    assert abs(frac - share) < 5 * np.sqrt(frac * (1 - frac) / N)
