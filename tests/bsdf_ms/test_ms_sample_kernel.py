"""The compiled sample() and approximate_pdf (sample_kernel) against the numpy reference, and
the closed-form Beckmann visible normals of the walk kernel seen from straight above."""

import numpy as np
import pytest
from scipy.stats import kstest

from model.bsdf import RoughConductor, RoughDielectric
from model.bsdf.distributions import make_distribution
from model.bsdf.multiple_scattering import Microsurface, RandomWalkBSDF
from model.bsdf.multiple_scattering.nee_kernel import AVAILABLE, Surface
from model.bsdf.multiple_scattering.visible_kernel import visible_normal

pytestmark = pytest.mark.skipif(not AVAILABLE, reason="the sample kernel needs numba (gonio[fast])")


def direction(theta_deg, phi_deg=0.0):
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])


SURFACES = [Microsurface("ggx", 0.3, "dielectric", eta=1.51),
            Microsurface("beckmann", 1.0, "dielectric", eta=1.51),
            Microsurface("beckmann", (0.9, 0.4), "conductor"),
            Microsurface("ggx", 0.1, "conductor", eta_complex=0.2 + 3.0j)]
INCIDENCES = [direction(0), direction(30, 40), direction(85), -direction(20, 200),
              -direction(70)]


@pytest.mark.parametrize("surface", SURFACES)
@pytest.mark.parametrize("wi", INCIDENCES)
def test_sample_returns_approximate_pdf_to_the_bit_and_it_matches_numpy(surface, wi):
    walk = RandomWalkBSDF(surface, walks=1)
    rng = np.random.default_rng(3)
    n = 4000
    wo, weight, pdf = walk.sample(np.broadcast_to(wi, (n, 3)), rng.random((n, 3)), rng)
    if surface.kind == "conductor" and wi[2] < 0:
        assert np.all(weight == 0) and np.all(pdf == 0)  # a conductor lit from below
        return
    ok = weight > 0
    assert ok.mean() > 0.99 and np.all(pdf[ok] > 0) and np.all(pdf[~ok] == 0)
    assert np.allclose(np.linalg.norm(wo, axis=-1), 1.0)
    compiled = walk.approximate_pdf(np.broadcast_to(wi, (n, 3)), wo)
    assert np.array_equal(pdf[ok], compiled[ok])
    assert np.array_equal(walk.approximate_pdf(wi, wo), compiled)  # one wi for all rows
    walk.walker.compiled = False  # the numpy reference
    reference = walk.approximate_pdf(np.broadcast_to(wi, (n, 3)), wo)
    assert np.allclose(compiled, reference, rtol=1e-12, atol=0.0)


@pytest.mark.parametrize("lobes", [("reflection",), ("transmission",)])
def test_sample_keeps_to_the_parents_lobes(lobes):
    glass = RoughDielectric("beckmann", 0.5, 1.51, masking="correlated", lobes=lobes,
                            multiple_scattering=True)
    rng = np.random.default_rng(4)
    n = 4000
    wo, weight, pdf = glass.sample(np.broadcast_to(direction(40), (n, 3)), rng.random((n, 3)),
                                   rng)
    kept = (wo[:, 2] > 0) == (lobes == ("reflection",))
    assert np.all(weight[~kept] == 0) and np.all(pdf[~kept] == 0)
    assert np.all(weight[kept] == 1.0) and np.all(pdf[kept] > 0)


def test_public_sample_shapes_and_one_direction():
    mirror = RoughConductor("ggx", 0.4, None, masking="correlated", multiple_scattering=True)
    rng = np.random.default_rng(5)
    wo, weight, pdf = mirror.sample(direction(20), rng.random(3), rng)
    assert wo.shape == (3,) and weight.shape == () and pdf.shape == ()
    wo, weight, pdf = mirror.sample(np.broadcast_to(direction(20), (2, 5, 3)),
                                    rng.random((2, 5, 3)), rng)
    assert wo.shape == (2, 5, 3) and weight.shape == (2, 5) and np.all(pdf > 0)


@pytest.mark.parametrize("alpha", [(0.3, 0.3), (1.0, 0.4)])
def test_beckmann_visible_normals_from_straight_above_are_the_slopes(alpha):
    """Seen from straight above every facet is visible as often as it is there: the slopes over
    alpha have the density exp(-x^2 - y^2) / pi, so their squared radius is Exp(1) and their
    azimuth uniform (the closed form both samplers take there)."""
    slopes = make_distribution("beckmann", alpha)
    s = Surface(int(slopes.kernel), *map(float, alpha), True, 1.0, False, 0j)
    u = np.random.default_rng(6).random((2, 20000))
    m = np.array([visible_normal(s, 0.0, 0.0, 1.0, a, b) for a, b in u.T])
    sx, sy = -m[:, 0] / m[:, 2] / alpha[0], -m[:, 1] / m[:, 2] / alpha[1]
    assert kstest(sx * sx + sy * sy, "expon").pvalue > 1e-3
    assert kstest(np.mod(np.arctan2(sy, sx), 2 * np.pi) / (2 * np.pi), "uniform").pvalue > 1e-3
    ref = slopes.sample_visible_sphere(np.broadcast_to([0.0, 0.0, 1.0], (200, 3)), u[0, :200],
                                       u[1, :200])
    assert np.allclose(m[:200], ref, atol=1e-9)
