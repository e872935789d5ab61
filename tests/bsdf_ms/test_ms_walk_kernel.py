"""The compiled walk against the numpy walk (same estimator, independent random numbers), and its
scalar special functions and visible-normal samplers against scipy and the numpy samplers."""

import numpy as np
import pytest
from scipy.special import erfcx as scipy_erfcx
from scipy.special import ndtri as scipy_ndtri
from scipy.stats import kstest

from model.bsdf import beckmann_sphere
from model.bsdf.distributions import make_distribution
from model.bsdf.multiple_scattering import Microsurface, RandomWalkBSDF
from model.bsdf.multiple_scattering.nee_kernel import AVAILABLE, Surface
from model.bsdf.multiple_scattering.random_kernel import uniform
from model.bsdf.multiple_scattering.visible_kernel import (
    START_THETA_MAX,
    _visible_slope,
    erfcx,
    ndtri,
    visible_normal,
)
from model.bsdf.multiple_scattering.walk import Walker
from model.bsdf.multiple_scattering.walk_kernel import scatter

pytestmark = pytest.mark.skipif(not AVAILABLE, reason="the walk kernel needs numba (gonio[fast])")
Z_MAX = 4.5


def direction(theta_deg, phi_deg=0.0):
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])


def test_ndtri_and_erfcx_match_scipy_to_full_precision():
    p = np.concatenate([np.logspace(-300, -1, 400), np.linspace(0.01, 0.99, 199),
                        1.0 - np.logspace(-16, -2, 50)])
    ours = np.array([ndtri(x) for x in p])
    assert np.allclose(ours, scipy_ndtri(p), rtol=2e-14, atol=1e-15)
    x = np.concatenate([np.linspace(0.0, 5.0, 201), np.logspace(0.5, 8, 100)])
    assert np.allclose([erfcx(v) for v in x], scipy_erfcx(x), rtol=1e-13)
    # libm's erfc times the exactly rounded exp(x^2), where the continued fraction was
    x = np.linspace(2.0, 25.0, 2301)
    assert np.allclose([erfcx(v) for v in x], scipy_erfcx(x), rtol=2e-15, atol=0.0)


@pytest.mark.parametrize("name,alpha", [("ggx", (0.3, 0.3)), ("beckmann", (0.3, 0.3)),
                                        ("beckmann", (1.0, 0.4)), ("ggx", (0.05, 0.8))])
def test_visible_normals_match_the_numpy_sampler_on_the_whole_sphere(name, alpha):
    slopes = make_distribution(name, alpha)
    rng = np.random.default_rng(1)
    w = rng.normal(size=(300, 3))
    w /= np.linalg.norm(w, axis=-1, keepdims=True)
    w[:3] = [direction(0), direction(180), direction(90, 30)]
    u = rng.random((2, 300))
    ref = slopes.sample_visible_sphere(w, u[0], u[1])
    s = Surface(int(slopes.kernel), *map(float, alpha), True, 1.0, False, 0j)
    ours = np.array([visible_normal(s, *w[i], u[0, i], u[1, i]) for i in range(300)])
    assert np.allclose(ours, ref, atol=1e-9)


def test_beckmann_slope_inversion_from_its_start_table_converges_everywhere():
    """Inside the start table (either side of the root), in its tail cells, across its theta edge
    and beyond it: the numpy inversion's slope to 1e-12 where u fixes it that well, and log F at
    its target to rounding everywhere (at u = 1 - 2^-53 a slope is only known to ~1e-2)."""
    rng = np.random.default_rng(4)
    theta = np.concatenate([rng.uniform(0.0, np.pi, 3000), np.full(200, START_THETA_MAX),
                            np.full(200, START_THETA_MAX + 1e-9), np.full(200, 1e-7),
                            np.full(200, np.pi / 2), np.full(200, np.pi - 1e-4)])
    u = rng.random(theta.size)
    u[-200:] = rng.uniform(0.98, 1.0, 200)  # near mu = -1e4, where log F's rounding cycled
    u[-1000:-200:4] = 1e-300
    u[-999:-200:4] = 1.0 - 2.0**-53
    u[-998:-200:4] = rng.uniform(0.0, 1.0 / 64.0, 200)
    mu = np.cos(theta) / np.sin(theta)
    ours = np.array([_visible_slope(m, v, t) for m, v, t in zip(mu, u, theta, strict=True)])
    assert np.all(ours <= mu)
    target = np.log(u) + beckmann_sphere._log_cdf(mu, mu)
    assert np.allclose(beckmann_sphere._log_cdf(ours, mu), target, rtol=1e-14, atol=1e-15)
    fixed = u < 1.0 - 1e-9
    ref = beckmann_sphere._visible_slope(mu[fixed], u[fixed])
    assert np.allclose(ours[fixed], ref, rtol=1e-12, atol=1e-12)


def _walkers(surface, guided):
    model = RandomWalkBSDF(surface, walks=1)
    return (Walker(model.slopes, model.micro, guided),
            Walker(model.slopes, model.micro, guided, compiled=False))


SURFACES = [Microsurface("ggx", 0.3, "dielectric", eta=1.5),
            Microsurface("beckmann", (0.9, 0.5), "dielectric", eta=1.5),
            Microsurface("beckmann", 0.4, "conductor", eta_complex=0.2 + 3.0j),
            Microsurface("ggx", 1.0, "conductor")]
PAIRS = [(direction(30), direction(50, 160)), (direction(70), direction(20, 10)),
         (direction(60), direction(130, 200)), (-direction(30), direction(120, 10)),
         (-direction(20), -direction(40, 180))]


def _mean_and_error(values):
    return values.mean(axis=0), values.std(axis=0, ddof=1) / np.sqrt(len(values))


@pytest.mark.parametrize("surface", SURFACES)
@pytest.mark.parametrize("guided", [True, False])
def test_compiled_eval_agrees_with_the_numpy_walk(surface, guided):
    fast, slow = _walkers(surface, guided)
    n = 6000
    for wi, wo in PAIRS:
        if surface.kind == "conductor" and (wi[2] < 0 or wo[2] < 0):
            continue
        args = (np.tile(wi, (n, 1)), None, np.tile(wo, (n, 1)))
        a = fast.run(args[0], np.random.default_rng(2), args[2]).value
        b = slow.run(args[0], np.random.default_rng(3), args[2]).value
        (ma, ea), (mb, eb) = _mean_and_error(a), _mean_and_error(b)
        assert ma > 0 and abs(ma - mb) < Z_MAX * np.hypot(ea, eb)


@pytest.mark.parametrize("surface", SURFACES[1:3])
def test_compiled_sampling_targets_and_cap_agree_with_the_numpy_walk(surface):
    fast, slow = _walkers(surface, False)
    wi = np.tile(direction(50, 20), (20000, 1))
    runs = [w.run(wi, np.random.default_rng(s), max_order=3) for w, s in ((fast, 4), (slow, 5))]
    for field in ("exit_direction", "weight", "truncated", "orders"):
        (ma, ea), (mb, eb) = (_mean_and_error(np.nan_to_num(getattr(r, field)).reshape(len(wi), -1))
                              for r in runs)
        assert np.all(np.abs(ma - mb) <= Z_MAX * np.hypot(ea, eb) + 1e-12), field
    targets = np.array([direction(t, p) for t in (10, 60, 120, 170) for p in (0, 135)])
    a, b = (w.run(wi[:4000], np.random.default_rng(s), targets=targets, min_order=2).value
            for w, s in ((fast, 6), (slow, 7)))
    (ma, ea), (mb, eb) = _mean_and_error(a), _mean_and_error(b)
    assert np.all(np.abs(ma - mb) <= Z_MAX * np.hypot(ea, eb) + 1e-12)


def test_compiled_walks_are_reproducible_from_the_generator():
    fast, _ = _walkers(SURFACES[0], True)
    wi, wo = np.tile(direction(40), (500, 1)), np.tile(direction(150, 20), (500, 1))
    a = fast.run(wi, np.random.default_rng(8), wo).value
    b = fast.run(wi, np.random.default_rng(8), wo).value
    c = fast.run(wi, np.random.default_rng(9), wo).value
    assert np.array_equal(a, b) and not np.array_equal(a, c)


def test_the_walks_generator_is_uniform_and_follows_its_state():
    state = np.random.default_rng(10).integers(0, 2**64, size=4, dtype=np.uint64)
    again = state.copy()
    u = np.array([uniform(state) for _ in range(20000)])
    assert np.all((u >= 0.0) & (u < 1.0)) and kstest(u, "uniform").pvalue > 1e-3
    assert np.all(u * 2.0**53 == np.floor(u * 2.0**53))  # 53-bit draws
    assert uniform(again) == u[0] and abs(np.corrcoef(u[:-1], u[1:])[0, 1]) < 0.03


@pytest.mark.parametrize("outside", [True, False])
def test_scatter_refracts_and_reflects_as_the_numpy_phase_function(outside):
    """The compiled scatter (Fresnel's e cos_t reused for the refraction) sends each w_in on
    a facet m where micro.scatter (Snell's law as written) does, to rounding, on both sides
    of glass and past total internal reflection."""
    surface = Microsurface("ggx", 0.3, "dielectric", eta=1.51)
    walker = RandomWalkBSDF(surface, walks=1).walker
    s = Surface(int(walker.slopes.kernel), 0.3, 0.3, False, 1.51, False, 0j)
    rng = np.random.default_rng(8)
    m = rng.normal(size=(400, 3)) * [0.5, 0.5, 1.0]
    m[:, 2] = np.abs(m[:, 2])
    m /= np.linalg.norm(m, axis=-1, keepdims=True)
    w_in = m + rng.normal(size=(400, 3))
    w_in /= np.linalg.norm(w_in, axis=-1, keepdims=True)
    facing = np.sum(w_in * m, axis=-1) > 0
    w_in, m, u = w_in[facing], m[facing], rng.random(facing.sum())
    side = np.full(len(u), outside)
    ref, _, crossed = walker.micro.scatter(walker.slopes, w_in, m, side, u[None, :], False)
    ours = np.array([scatter(s, outside, *w_in[k], *m[k], u[k], 0.0) for k in range(len(u))])
    assert np.array_equal(ours[:, 4].astype(bool), crossed) and 0 < crossed.sum() < len(u)
    np.testing.assert_allclose(ours[:, :3], ref, rtol=0, atol=1e-14)
    assert np.all(ours[:, 3] == 1.0)  # branches drawn by F itself: factor 1
