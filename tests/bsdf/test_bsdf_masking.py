"""Height-correlated masking for transmission, G2 = B(1 + Li, 1 + Lo) (Heitz 2014): its stable
log-Beta against mpmath over Lambda up to 1e100, against the height integral it comes from, and
the compiled version against the numpy one."""

import mpmath as mp
import numpy as np
import pytest

from model.bsdf.kernels import AVAILABLE
from model.bsdf.masking import beta_over_cosines, g2_over_cosines, log_beta

ARGS = [1.0, 1.0 + 1e-12, 1.3, 2.0, 9.99, 10.0, 10.01, 31.4, 1e3, 1e5, 1e9, 1e17, 1e100]


def test_log_beta_matches_mpmath_from_1_to_1e100():
    """|error| <= 1e-15 max(1, |log B|): a few ulp of the result's own size, no cancellation
    between large log Gammas (which would cost ~1e-6 at arguments of 1e9)."""
    p, q = (a.ravel() for a in np.meshgrid(ARGS, ARGS))
    ours = log_beta(p, q)
    with mp.workdps(250):  # 1e100 + 1.3 needs more than 100 digits
        exact = np.array([float(mp.log(mp.beta(mp.mpf(a), mp.mpf(b))))
                          for a, b in zip(p, q, strict=True)])
    err = np.abs(ours - exact) / np.maximum(np.abs(exact), 1.0)
    assert err.max() < 1e-15
    np.testing.assert_array_equal(ours, log_beta(q, p))  # symmetric: reciprocity


@pytest.mark.parametrize("li,lo", [(0.0, 0.0), (0.3, 0.0), (0.7, 2.5), (4.0, 0.05)])
def test_beta_is_the_height_integral(li, lo):
    """G2 = int_0^1 u^Li (1 - u)^Lo du: one direction unmasked above height CDF u, the other
    below it (quadrature at 30 digits, not the Beta identity)."""
    with mp.workdps(30):
        exact = mp.quad(lambda u: u ** li * (1 - u) ** lo, [0, 0.5, 1])
    ci, co = 0.6, 0.25
    g = g2_over_cosines("correlated", ci, co, ci * li, co * lo, True) * ci * co
    assert float(g) == pytest.approx(float(exact), rel=1e-13)
    reflected = g2_over_cosines("correlated", ci, co, ci * li, co * lo, False) * ci * co
    assert float(reflected) == pytest.approx(1 / (1 + li + lo), rel=1e-15)
    assert g <= reflected  # masked from both sides of a height is rarer than from one


def test_beta_over_cosines_at_grazing_and_infinite_lambda():
    """Finite and >= 0 from 1e-100 to 1 in both cosines; 0 for an infinite Lambda (Phong
    beyond alpha sqrt 2) or a zero cosine."""
    c = np.array([1e-100, 1e-30, 1e-9, 1e-3, 0.5, 1.0])
    ci, co = (a.ravel() for a in np.meshgrid(c, c))
    li, lo = 0.4 * np.sqrt(1 - ci**2), 0.4 * np.sqrt(1 - co**2)
    g = beta_over_cosines(ci, co, li, lo)
    assert np.all(np.isfinite(g)) and np.all(g >= 0)
    one_grazing = (ci == 1e-9) & (co == 1.0)  # B(1 + L, 1) / ci = 1 / (ci + li) exactly
    assert g[one_grazing][0] == pytest.approx(1 / (1e-9 + li[one_grazing][0]), rel=1e-14)
    assert beta_over_cosines(0.5, 0.5, np.inf, 0.1) == 0 and beta_over_cosines(0.0, 0.5, 0.1,
                                                                                0.1) == 0


@pytest.mark.skipif(not AVAILABLE, reason="numba (gonio[fast]) is not installed")
def test_compiled_beta_matches_numpy():
    from model.bsdf.primitives import beta_over_cosines as _beta_oc

    rng = np.random.default_rng(0)
    ci, co = 10.0 ** rng.uniform(-100, 0, (2, 2000))
    li, lo = 10.0 ** rng.uniform(-20, 1, (2, 2000))
    ours = beta_over_cosines(ci, co, li, lo)
    fast = np.array([_beta_oc(*args) for args in zip(ci, co, li, lo, strict=True)])
    rel = np.abs(fast - ours) / np.where(ours > 0, ours, 1.0)
    assert np.array_equal(fast > 0, ours > 0) and rel.max() < 1e-13
