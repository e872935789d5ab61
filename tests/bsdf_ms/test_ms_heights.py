"""Height distributions of the random walk: CDFs, stable inverses at the tails, first hits."""

import mpmath
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from model.bsdf.multiple_scattering import Microsurface, RandomWalkBSDF
from model.bsdf.multiple_scattering.heights import (
    GaussianHeights,
    UniformHeights,
    log1mexp,
    make_heights,
)

mpmath.mp.dps = 50


def log_phi(h) -> float:
    """log Phi(h) in 50-digit arithmetic, from whichever tail keeps the digits."""
    h = mpmath.mpf(h)
    return float(mpmath.log(mpmath.ncdf(h)) if h < 0 else mpmath.log1p(-mpmath.ncdf(-h)))


def test_gaussian_log_cdf_matches_mpmath_in_both_tails():
    g = GaussianHeights()
    for h in (-38.0, -10.0, -1.0, 0.0, 2.0, 9.0, 30.0):
        exact = log_phi(h)
        exact_sf = log_phi(-h)
        assert g.log_cdf(h) == pytest.approx(exact, rel=1e-13, abs=1e-300)
        assert g.log_sf(h) == pytest.approx(exact_sf, rel=1e-13, abs=1e-300)


@pytest.mark.parametrize("log_u", [-700.0, -40.0, -1.0, np.log(0.5), -1e-5, -1e-12, -1e-200])
def test_gaussian_inverse_is_exact_near_zero_and_one(log_u):
    """Phi(h) checked in 50-digit arithmetic: log Phi(h) and log(1 - Phi(h)) both to ~1e-12."""
    h = mpmath.mpf(float(GaussianHeights().inv_log_cdf(np.array(log_u))))
    assert log_phi(h) == pytest.approx(log_u, rel=1e-11)
    assert log_phi(-h) == pytest.approx(float(log1mexp(np.array(log_u))), rel=1e-11)


@pytest.mark.parametrize("log_u", [-700.0, -30.0, -1.0, -1e-9, -1e-18])
def test_uniform_inverse_is_right_to_the_float_spacing_at_both_ends(log_u):
    """Near h = -1 or h = 1 a float64 height carries its distance to the end only to ~1e-16:
    the inverse is right to that spacing (which is why the walk itself runs in log C1)."""
    h = float(UniformHeights().inv_log_cdf(np.array(log_u)))
    u = mpmath.exp(mpmath.mpf(log_u))
    assert h == pytest.approx(float(2 * u - 1), abs=2.3e-16)


@settings(max_examples=200, deadline=None)
@given(st.floats(min_value=-37.0, max_value=8.0))
def test_gaussian_roundtrip(h):
    g = GaussianHeights()
    back = float(g.inv_log_cdf(g.log_cdf(np.array(h))))
    assert back == pytest.approx(h, rel=1e-9, abs=1e-9)


@settings(max_examples=200, deadline=None)
@given(st.floats(min_value=-1.0, max_value=1.0))
def test_uniform_roundtrip(h):
    u = UniformHeights()
    assert float(u.inv_log_cdf(u.log_cdf(np.array(h)))) == pytest.approx(h, abs=1e-15)
    assert float(u.cdf(np.array(h))) == pytest.approx(0.5 * (1 + h), abs=5e-16)


@settings(max_examples=200, deadline=None)
@given(st.floats(min_value=-745.0, max_value=-1e-300))
def test_log1mexp_against_mpmath(x):
    y = mpmath.mpf(x)
    exact = float(mpmath.log(-mpmath.expm1(y)) if x > -1 else mpmath.log1p(-mpmath.exp(y)))
    assert float(log1mexp(np.array(x))) == pytest.approx(exact, rel=1e-13, abs=1e-300)


@pytest.mark.parametrize("height", ["uniform", "gaussian"])
def test_first_hit_heights_follow_c1_to_the_power_one_plus_lambda(height):
    """A ray from above first meets the surface below h with probability C1(h)^(1 + Lambda(wi))."""
    model = RandomWalkBSDF(Microsurface("ggx", 0.7, "conductor"), height=height)
    theta = np.radians(70.0)
    wi = np.array([np.sin(theta), 0.0, np.cos(theta)])
    lam = float(model.slopes.signed_lambda(wi[None])[0])
    h = model.first_heights(wi, np.random.default_rng(5), 20000)
    dist = make_heights(height)
    result = stats.kstest(h, lambda x: dist.cdf(x) ** (1.0 + lam))
    assert result.pvalue > 1e-3


@pytest.mark.parametrize("height", ["uniform", "gaussian"])
def test_density_is_the_derivative_of_the_cdf_and_inv_cdf_inverts_it(height):
    dist = make_heights(height)
    h = np.linspace(-0.99, 0.99, 199) * (1 if height == "uniform" else 6)
    step = 1e-6
    low = (dist.cdf(h + step) - dist.cdf(h - step)) / (2 * step)
    high = (np.exp(dist.log_sf(h - step)) - np.exp(dist.log_sf(h + step))) / (2 * step)
    numeric = np.where(h < 0, low, high)  # each from its own tail, to keep the digits
    assert np.allclose(dist.pdf(h), numeric, rtol=1e-6, atol=1e-12)
    u = np.linspace(1e-9, 1 - 1e-9, 101)
    assert np.allclose(dist.cdf(dist.inv_cdf(u)), u, rtol=1e-12, atol=1e-15)


def test_bad_height_name_is_one_clear_error():
    with pytest.raises(ValueError, match="height must be one of"):
        make_heights("lognormal")
