"""Sampling against densities: chi-square of sample() vs pdf(), of the distributions' normal
samplers vs their densities, and weight == f |cos o| / pdf for every returned sample."""

import numpy as np
import pytest
from bsdf_quadrature import chi_square_pvalue, direction

from model.bsdf import RoughConductor, RoughDielectric, make_distribution

N = 100_000
P_MIN = 1e-3  # per test; about 40 tests, so a false alarm is unlikely at fixed seeds

DIELECTRIC_CASES = [
    # distribution, alpha, eta, sampling, theta_i (rad; > pi/2 = from the interior), masking
    ("ggx", 0.3, 1.51, "visible", 0.5, "separable"),
    ("ggx", 0.6, 1.51, "walter", 1.2, "correlated"),
    ("ggx", (0.2, 0.6), 1.33, "visible", 1.0, "separable"),
    ("ggx", 0.3, 1.51, "visible", np.pi - 0.3, "correlated"),
    ("ggx", 1.0, 1.51, "walter", np.pi - 0.9, "separable"),
    ("beckmann", 0.3, 1.51, "visible", 0.7, "separable"),
    ("beckmann", 0.5, 1.51, "walter", 0.2, "correlated"),
    ("beckmann", (0.5, 0.15), 2.5, "visible", 1.3, "correlated"),
    ("beckmann", 0.4, 1.51, "visible", np.pi - 0.6, "separable"),
    ("phong", 0.3, 1.51, "walter", 0.6, "separable"),
    ("phong", 0.7, 1.2, "walter", np.pi - 0.4, "correlated"),
]


def _check(model, wi, seed):
    u = np.random.default_rng(seed).random((N, 3))
    wo, weight, pdf = model.sample(wi, u)
    ok = pdf > 0
    p_value, mass = chi_square_pvalue(wo[ok], lambda d: model.pdf(wi, d))
    assert p_value > P_MIN
    # fraction of valid samples = integral of pdf (binomial error, quadrature error)
    frac = ok.mean()
    assert abs(frac - mass) < 5 * np.sqrt(max(frac * (1 - frac), 1e-4) / N) + 2e-3
    # weight = f |cos o| / pdf, sample pdf = pdf()
    f = model.eval(wi, wo[ok])
    np.testing.assert_allclose(weight[ok], f * np.abs(wo[ok, 2]) / pdf[ok], rtol=1e-10)
    np.testing.assert_allclose(model.pdf(wi, wo[ok]), pdf[ok], rtol=1e-9)
    assert np.all(weight[~ok] == 0) and np.all(np.isfinite(weight))


@pytest.mark.parametrize("case", DIELECTRIC_CASES, ids=str)
def test_dielectric_sampling_matches_pdf(case):
    dist, alpha, eta, sampling, theta, masking = case
    model = RoughDielectric(dist, alpha, eta, masking=masking, sampling=sampling)
    _check(model, direction(theta, 0.4), seed=len(str(case)))


@pytest.mark.parametrize("lobe", ["reflection", "transmission"])
@pytest.mark.parametrize("theta", [0.4, np.pi - 0.5])
def test_single_lobe_sampling_matches_pdf(lobe, theta):
    model = RoughDielectric("ggx", 0.4, 1.51, lobes=(lobe,))
    _check(model, direction(theta, 1.0), seed=7)


@pytest.mark.parametrize("dist,alpha,sampling", [
    ("ggx", 0.3, "visible"), ("beckmann", (0.2, 0.5), "visible"), ("ggx", 0.5, "walter"),
    ("phong", 0.4, "walter")])
def test_conductor_sampling_matches_pdf(dist, alpha, sampling):
    model = RoughConductor(dist, alpha, 0.2 + 3.1j, sampling=sampling)
    _check(model, direction(0.9, 2.0), seed=11)


NORMAL_CASES = [("ggx", 0.3), ("ggx", (0.15, 0.7)), ("beckmann", 0.5), ("beckmann", (0.6, 0.2)),
                ("phong", 0.4)]


@pytest.mark.parametrize("name,alpha", NORMAL_CASES)
def test_sample_normal_matches_pdf_normal(name, alpha):
    d = make_distribution(name, alpha)
    u = np.random.default_rng(3).random((N, 2))
    m = d.sample_normal(u[:, 0], u[:, 1])
    p_value, mass = chi_square_pvalue(m, d.pdf_normal)
    assert p_value > P_MIN
    assert abs(mass - 1) < 2e-3


@pytest.mark.parametrize("name,alpha", NORMAL_CASES[:4])
@pytest.mark.parametrize("theta", [0.0, 0.8, 1.45])
def test_sample_visible_matches_pdf_visible(name, alpha, theta):
    d = make_distribution(name, alpha)
    w = direction(theta, 0.7)
    u = np.random.default_rng(5).random((N, 2))
    m = d.sample_visible(w, u[:, 0], u[:, 1])
    p_value, mass = chi_square_pvalue(m, lambda x: d.pdf_visible(w, x))
    assert p_value > P_MIN
    assert abs(mass - 1) < 2e-3
