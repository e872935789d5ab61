"""The vectorised numpy formulas (distributions, masking, fresnel, microfacet) agree with the
scalar source in primitives.py, compiled or (without numba) as plain Python, formula by
formula; the model-level kernels are held to the numpy path in test_bsdf_kernels.py."""

import numpy as np
import pytest

from model.bsdf import primitives as p
from model.bsdf.constants import BECKMANN_KERNEL_TAIL_FROM, Masking, Ndf, Sampling
from model.bsdf.distributions import (
    DISTRIBUTIONS,
    WITH_KERNELS,
    beckmann_a_lambda,
    make_distribution,
)
from model.bsdf.fresnel import (
    dielectric_transmittance,
    fresnel_conductor,
    reflectance_transmittance_toward,
)
from model.bsdf.masking import MASKINGS, g2_over_cosines, log_beta, masking_kind
from model.bsdf.microfacet import SAMPLINGS, walter_widening

ALPHAS = [(0.3, 0.3), (0.05, 0.9), (2.0, 1e-3)]
#: Relative agreement: the same formulas in the same order; numpy's exp and log may differ
#: from libm's by an ulp, which Beckmann's exp(-X) amplifies by X.
RTOL = 1e-13


def _scalar(fn, *columns):
    """fn applied row by row to the columns (scalars broadcast), as a float array; enum
    members arrive as plain ints, as compiled callers pass them."""
    columns = np.broadcast_arrays(*(np.asarray(c) for c in columns))
    return np.array([fn(*(c.item() for c in row)) for row in zip(*columns, strict=True)])


def _directions(n, seed, upper=False):
    rng = np.random.default_rng(seed)
    w = rng.normal(size=(n, 3))
    w[:3] = [[0.0, 0.0, 1.0], [1.0, 0.0, 1e-9], [0.3, -0.2, 1e-12]]  # normal, near grazing
    if upper:
        w[:, 2] = np.abs(w[:, 2])
    return w / np.linalg.norm(w, axis=1, keepdims=True)


def _kernel_distributions():
    return [(name, alpha) for name in WITH_KERNELS for alpha in ALPHAS]


def test_identities_match_the_registries():
    assert {DISTRIBUTIONS[name].kernel for name in WITH_KERNELS} == set(Ndf)
    assert [masking_kind(m) for m in MASKINGS] == list(Masking)
    assert [Sampling[s.upper()] for s in SAMPLINGS] == list(Sampling)


@pytest.mark.parametrize("name,alpha", _kernel_distributions())
def test_normal_density_and_cos_lambda(name, alpha):
    d = make_distribution(name, alpha)
    m = _directions(3000, 1, upper=True)
    w = _directions(3000, 2)
    np.testing.assert_allclose(_scalar(p.normal_density, d.kernel, *alpha, *m.T), d.D(m),
                               rtol=RTOL, atol=0)
    np.testing.assert_allclose(_scalar(p.cos_lambda, d.kernel, *alpha, *w.T), d.cos_lambda(w),
                               rtol=RTOL, atol=0)


def test_beckmann_a_lambda_both_branches():
    a = np.concatenate([np.geomspace(1e-8, 30.0, 400), [0.0, 2.0, np.inf]])
    np.testing.assert_allclose(_scalar(p.beckmann_a_lambda, a), beckmann_a_lambda(a),
                               rtol=RTOL, atol=0)


def test_beckmann_a_lambda_matches_mpmath_in_every_branch():
    """The closed form to a = 2, the closed form with exp(-a^2) exactly rounded to
    BECKMANN_KERNEL_TAIL_FROM, Cody's tail of erfc beyond it: within 3e-14 of 40 digits."""
    import mpmath

    a = np.concatenate([np.geomspace(1e-6, 2.0, 60), np.random.default_rng(5).uniform(2, 26, 600),
                        [BECKMANN_KERNEL_TAIL_FROM, np.nextafter(BECKMANN_KERNEL_TAIL_FROM, 0.0)]])
    with mpmath.workdps(40):
        exact = np.array([float((mpmath.exp(-mpmath.mpf(x) ** 2) / mpmath.sqrt(mpmath.pi)
                                 - x * mpmath.erfc(x)) / 2) for x in a])
    np.testing.assert_allclose(_scalar(p.beckmann_a_lambda, a), exact, rtol=3e-14, atol=0)
    # past a = 27.3 exp(-a^2) is 0; from 1.3e154 on a^2 overflows (it gave nan, not 0)
    huge = np.array([27.5, 1e160, 1e300, 1.7e308, np.inf])
    assert np.all(_scalar(p.beckmann_a_lambda, huge) == 0.0)


def test_log_beta_in_all_three_regions():
    rng = np.random.default_rng(3)
    x, y = 10.0 ** rng.uniform(0.0, 12.0, (2, 3000))
    np.testing.assert_allclose(_scalar(p.log_beta, x, y), log_beta(x, y), rtol=RTOL, atol=1e-15)


@pytest.mark.parametrize("masking", MASKINGS)
@pytest.mark.parametrize("transmitted", [False, True])
def test_g2_over_cosines(masking, transmitted):
    rng = np.random.default_rng(4)
    ci, co = 10.0 ** rng.uniform(-30.0, 0.0, (2, 2000))
    li, lo = 10.0 ** rng.uniform(-10.0, 2.0, (2, 2000))
    ours = g2_over_cosines(masking, ci, co, li, lo, transmitted)
    scalar = _scalar(p.g2_over_cosines, masking_kind(masking), ci, co, li, lo, transmitted)
    # transmission is exp(log B - log ci - log co): the exp turns an ulp of a log of up to
    # ~700 into a few 1e-13 relative
    np.testing.assert_allclose(scalar, ours, rtol=5e-13 if transmitted else RTOL, atol=0)


@pytest.mark.parametrize("e", [1.51, 1 / 1.51, 1.0 + 1e-12, 4.0])
def test_dielectric_fresnel(e):
    c = np.concatenate([np.geomspace(1e-12, 1.0, 500), [0.3, 0.66, 0.99]])
    em1 = e - 1.0
    f, t = reflectance_transmittance_toward(c, e, em1)
    np.testing.assert_allclose(_scalar(p.fresnel_toward, c, e, em1), f, rtol=RTOL, atol=0)
    e_ct = np.sqrt(np.maximum(em1 * (e + 1.0) + c * c, 0.0))
    live = e_ct > 0
    np.testing.assert_allclose(_scalar(p.transmittance_e, c[live], e_ct[live], e), t[live],
                               rtol=RTOL, atol=0)
    ct = e_ct[live] / e
    np.testing.assert_allclose(_scalar(p.dielectric_transmittance, c[live], ct, e),
                               dielectric_transmittance(c[live], ct, e), rtol=RTOL, atol=0)


@pytest.mark.parametrize("n", [0.2 + 3.1j, 1.5 + 0j, 1.0 + 0j, 1.0 + 1e-9j])
def test_conductor_fresnel(n):
    c = np.concatenate([np.geomspace(1e-12, 1.0, 500), [0.0]])
    np.testing.assert_allclose(_scalar(p.conductor_fresnel, c, True, n), fresnel_conductor(c, n),
                               rtol=RTOL, atol=0)
    assert p.conductor_fresnel(0.4, False, 0j) == 1.0


@pytest.mark.parametrize("name,alpha", _kernel_distributions())
def test_walter_sampling_and_its_density(name, alpha):
    d = make_distribution(name, alpha)
    wi = _directions(2000, 5, upper=True)
    u1, u2 = np.random.default_rng(6).random((2, 2000))
    widened = d.scaled(walter_widening(wi[:, 2]))
    m = widened.sample_normal(u1, u2)
    np.testing.assert_allclose(_scalar(p.walter_scale, wi[:, 2]), walter_widening(wi[:, 2]),
                               rtol=0, atol=0)
    scalar_m = np.array([p.walter_normal(int(d.kernel), *alpha, iz, a, b)
                         for iz, a, b in zip(wi[:, 2], u1, u2, strict=True)])
    np.testing.assert_allclose(scalar_m, m, rtol=0, atol=1e-15)
    np.testing.assert_allclose(
        _scalar(p.normal_pdf, d.kernel, *alpha, Sampling.WALTER, *wi.T, *m.T),
        widened.pdf_normal(m), rtol=RTOL, atol=0)


@pytest.mark.parametrize("alpha", ALPHAS)
def test_ggx_visible_sampling_and_its_density(alpha):
    d = make_distribution("ggx", alpha)
    wi = _directions(2000, 7, upper=True)
    u1, u2 = np.random.default_rng(8).random((2, 2000))
    m = d.sample_visible(wi, u1, u2)
    scalar_m = np.array([p.sample_normal(int(Ndf.GGX), *alpha, int(Sampling.VISIBLE), *w, a,
                                         b)
                         for w, a, b in zip(wi, u1, u2, strict=True)])
    # sqrt(1 - p1^2 - p2^2) near the disk's rim turns an ulp of cos / sin into ~1e-14
    np.testing.assert_allclose(scalar_m, m, rtol=0, atol=1e-12)
    np.testing.assert_allclose(
        _scalar(p.normal_pdf, Ndf.GGX, *alpha, Sampling.VISIBLE, *wi.T, *m.T),
        d.pdf_visible(wi, m), rtol=RTOL, atol=0)


def test_cos_sin_2pi_matches_numpy_in_every_quadrant():
    """The walk's and the SIMD sampler's cos and sin of 2 pi u (fdlibm's kernels after an
    exact quadrant split) stay within 1e-15 of numpy's, at the quadrant edges too."""
    u = np.concatenate([np.linspace(0.0, 1.0, 4001), np.random.default_rng(7).random(4000),
                        np.array([0.125, 0.375, 0.625, 0.875]) + 1e-17])
    ours = _scalar(p.cos_sin_2pi, u)
    assert np.max(np.abs(ours[:, 0] - np.cos(2 * np.pi * u))) < 1e-15
    assert np.max(np.abs(ours[:, 1] - np.sin(2 * np.pi * u))) < 1e-15


@pytest.mark.parametrize("e", [1.51, 1 / 1.51])
def test_fresnel_e_ct_is_fresnel_and_the_scaled_transmitted_cosine(e):
    c = np.concatenate([np.geomspace(1e-12, 1.0, 500), [0.3, 0.66, 0.99]])
    f, e_ct = _scalar(p.fresnel_e_ct, c, e, e - 1.0).T
    assert np.array_equal(f, _scalar(p.fresnel_toward, c, e, e - 1.0))
    live = e * e - 1.0 + c * c > 0  # 0 under total internal reflection
    np.testing.assert_allclose(e_ct[live], np.sqrt(e * e - 1.0 + c[live] ** 2), rtol=1e-14)
    assert np.all(e_ct[~live] == 0.0) and np.all(f[~live] == 1.0)
