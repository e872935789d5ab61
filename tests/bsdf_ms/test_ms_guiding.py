"""Guided next-direction sampling: the backwards proposal matches its density; no bias."""

import numpy as np
import pytest

from model.bsdf.distributions import WALKABLE, make_distribution
from model.bsdf.multiple_scattering import Microsurface, RandomWalkBSDF, albedo_estimate
from model.bsdf.multiple_scattering.guiding import adjoint_density, sample_adjoint


def direction(theta_deg, phi_deg=0.0):
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])


@pytest.mark.parametrize("theta", [30.0, 75.0, 120.0, 160.0])
@pytest.mark.parametrize("name", WALKABLE)
def test_backwards_proposal_has_the_density_it_reports(theta, name):
    """E[g(w)] over proposal samples = integral of g p over the sphere (uniform quadrature),
    for g = 1 (total mass of the successful draws), w_z and w_x."""
    slopes = make_distribution(name, (0.5, 0.35))
    wo = direction(theta, 30.0)
    eta = np.full(1, 1.5 if theta < 90 else 1 / 1.5)
    rng = np.random.default_rng(1)
    n = 200000
    u = rng.random((2, n))
    w, ok = sample_adjoint(slopes, np.broadcast_to(wo, (n, 3)), np.broadcast_to(eta, n), *u)
    z = 2 * rng.random(n) - 1
    phi = 2 * np.pi * rng.random(n)
    r = np.sqrt(1 - z * z)
    sphere = np.stack([r * np.cos(phi), r * np.sin(phi), z], -1)
    p = adjoint_density(slopes, sphere, np.broadcast_to(wo, (n, 3)), np.broadcast_to(eta, n))
    for g in (lambda v: np.ones(v.shape[:-1]), lambda v: v[..., 2], lambda v: v[..., 0]):
        sampled = np.where(ok, g(w), 0.0)
        quad = g(sphere) * p * 4 * np.pi
        se = np.hypot(sampled.std(), quad.std()) / np.sqrt(n)
        assert abs(sampled.mean() - quad.mean()) < 4.5 * se + 1e-3


GUIDED_CASES = [
    ("conductor", direction(30), direction(50, 160)),
    ("conductor", direction(75), direction(20, 10)),
    ("dielectric", direction(30), direction(50, 160)),
    ("dielectric", direction(30), direction(150, 0)),
    ("dielectric", direction(60), direction(170, 180)),
    ("dielectric", -direction(25), direction(70, 40)),
]


@pytest.mark.parametrize("kind,wi,wo", GUIDED_CASES)
def test_guided_and_plain_walks_agree(kind, wi, wo):
    surface = Microsurface("ggx", 0.3, kind, eta=1.5, eta_complex=0.3 + 2.5j)
    guided = RandomWalkBSDF(surface, walks=60000, guided=True)
    plain = RandomWalkBSDF(surface, walks=60000, guided=False)
    a = guided.estimate(wi, wo, np.random.default_rng(2))
    b = plain.estimate(wi, wo, np.random.default_rng(3))
    assert a.value > 0 and abs(a.value - b.value) < 4.5 * np.hypot(a.stderr, b.stderr)


def test_guided_walk_keeps_the_white_furnace():
    model = RandomWalkBSDF(Microsurface("ggx", 1.0, "dielectric", eta=1.5), walks=1,
                           guided=True)
    value, err = albedo_estimate(model, direction(70), np.random.default_rng(4), 40000)
    assert abs(value - 1.0) < 4.5 * err


def test_guiding_default_follows_roughness():
    assert RandomWalkBSDF(Microsurface("ggx", 0.3)).guided
    assert not RandomWalkBSDF(Microsurface("ggx", 1.0)).guided
