"""The random-walk BSDF: energy, order 1 against the analytic model, reciprocity, sampling, caps."""

import numpy as np
import pytest

from model.bsdf import RoughConductor, RoughDielectric
from model.bsdf.distributions import WALKABLE
from model.bsdf.multiple_scattering import (
    Microsurface,
    RandomWalkBSDF,
    albedo_estimate,
    energy_loss,
    sample_kernel,
)

Z_MAX = 4.5  # |z-score| allowed for a Monte Carlo comparison (deterministic seeds)


def direction(theta_deg, phi_deg=0.0):
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])


@pytest.mark.parametrize("name,alpha", [("ggx", 0.3), ("ggx", 1.0), ("beckmann", 1.0),
                                        ("ggx", (1.0, 0.3))])
@pytest.mark.parametrize("theta", [0.0, 60.0, 85.0])
def test_white_furnace_conductor_f1(name, alpha, theta):
    model = RandomWalkBSDF(Microsurface(name, alpha, "conductor"), walks=1)
    value, err = albedo_estimate(model, direction(theta, 20.0), np.random.default_rng(1), 40000)
    assert abs(value - 1.0) < Z_MAX * err and err < 0.03


@pytest.mark.parametrize("name,alpha", [("ggx", 0.3), ("ggx", 1.0), ("beckmann", 1.0)])
@pytest.mark.parametrize("theta", [0.0, 60.0, 85.0, 130.0, 175.0])
def test_dielectric_reflection_plus_transmission_is_one(name, alpha, theta):
    """R + T = 1 from outside (theta < 90) and from inside the glass (theta > 90)."""
    model = RandomWalkBSDF(Microsurface(name, alpha, "dielectric", eta=1.5), walks=1)
    value, err = albedo_estimate(model, direction(theta, 20.0), np.random.default_rng(2), 40000)
    assert abs(value - 1.0) < Z_MAX * err and err < 0.05


def test_diffuse_microsurface_energy():
    """Albedo 1 facets conserve energy; albedo a scales order k by a^k: E(a) = sum a^k E_k(1)."""
    wi = direction(50.0)
    rng = np.random.default_rng(3)
    white = RandomWalkBSDF(Microsurface("ggx", 1.0, "diffuse", albedo=1.0), walks=1)
    value, err = albedo_estimate(white, wi, rng, 30000)
    assert abs(value - 1.0) < Z_MAX * err
    orders = [albedo_estimate(white, wi, rng, 20000, order=k) for k in range(1, 9)]
    series = sum(0.5**k * e for k, (e, _) in enumerate(orders, start=1))
    series_err = np.sqrt(sum((0.5**k * s) ** 2 for k, (_, s) in enumerate(orders, start=1)))
    grey = RandomWalkBSDF(Microsurface("ggx", 1.0, "diffuse", albedo=0.5), walks=1)
    value, err = albedo_estimate(grey, wi, rng, 30000)
    assert abs(value - series) < Z_MAX * np.hypot(err, series_err) + 0.5**9


PAIRS = [
    (direction(30), direction(50, 160)),  # reflection
    (direction(70), direction(20, 10)),  # reflection
    (direction(30), direction(160, 170)),  # transmission
    (direction(60), direction(130, 200)),  # transmission
    (-direction(30), direction(120, 10)),  # reflection inside the glass
    (-direction(20), -direction(40, 180)),  # transmission from the glass
]


@pytest.mark.parametrize("name", WALKABLE)
@pytest.mark.parametrize("wi,wo", PAIRS)
def test_order_one_is_the_height_correlated_single_scattering_model(name, wi, wo):
    single = RoughDielectric(name, (0.6, 0.3), 1.5, masking="correlated")
    walk = RandomWalkBSDF(single, walks=60000)
    est = walk.estimate(wi, wo, np.random.default_rng(4), order=1)
    expected = single.eval(wi, wo)  # its transmission G2 is the Beta form the walk produces
    assert expected > 0
    assert abs(est.value - expected) <= Z_MAX * est.stderr + 1e-12 * expected


def test_order_one_of_a_fresnel_conductor():
    single = RoughConductor("beckmann", 0.5, 0.2 + 3.0j, masking="correlated")
    walk = RandomWalkBSDF(single, walks=20000)
    wi, wo = direction(40), direction(65, 120)
    est = walk.estimate(wi, wo, np.random.default_rng(5), order=1)
    assert abs(est.value - single.eval(wi, wo)) <= Z_MAX * est.stderr + 1e-12


@pytest.mark.parametrize("wi,wo", [(direction(30), direction(50, 160)),
                                   (direction(80), direction(10, 30)),
                                   (direction(30), direction(160, 170)),
                                   (direction(75), direction(110, 40)),
                                   (-direction(20), -direction(60, 100))])
def test_reciprocity_and_generalised_reciprocity(wi, wo):
    """f(i,o) / eta_o^2 = f(o,i) / eta_i^2 (eta of the side each direction lies on)."""
    walk = RandomWalkBSDF(Microsurface("ggx", 0.8, "dielectric", eta=1.5), walks=40000)
    a = walk.estimate(wi, wo, np.random.default_rng(6))
    b = walk.estimate(wo, wi, np.random.default_rng(7))
    eta_i = 1.5 if wi[2] < 0 else 1.0
    eta_o = 1.5 if wo[2] < 0 else 1.0
    x, y = a.value / eta_o**2, b.value / eta_i**2
    assert x > 0 and abs(x - y) < Z_MAX * np.hypot(a.stderr / eta_o**2, b.stderr / eta_i**2)


def test_conductor_reciprocity():
    walk = RandomWalkBSDF(Microsurface("beckmann", (0.9, 0.5), "conductor"), walks=40000)
    wi, wo = direction(70, 10), direction(25, 140)
    a = walk.estimate(wi, wo, np.random.default_rng(8))
    b = walk.estimate(wo, wi, np.random.default_rng(9))
    assert abs(a.value - b.value) < Z_MAX * np.hypot(a.stderr, b.stderr)


def test_single_orders_add_up_to_the_full_walk():
    walk = RandomWalkBSDF(Microsurface("ggx", 1.0, "conductor"), walks=40000)
    wi, wo = direction(60), direction(40, 200)
    rng = np.random.default_rng(10)
    orders = [walk.estimate(wi, wo, rng, order=k) for k in (1, 2, 3)]
    higher = walk.estimate(wi, wo, rng)
    capped = RandomWalkBSDF(Microsurface("ggx", 1.0, "conductor"), walks=40000, max_order=3)
    first3 = capped.estimate(wi, wo, rng)
    total = sum(o.value for o in orders)
    err = np.sqrt(sum(o.stderr**2 for o in orders) + first3.stderr**2)
    assert all(o.value > 0 for o in orders)
    assert abs(total - first3.value) < Z_MAX * err
    assert higher.value > first3.value  # orders >= 4 add a positive amount
    assert np.all(orders[0].truncated_energy == 0) and first3.truncated_energy > 0.01


def test_order_cap_reports_its_bias():
    """With a cap, energy returned + energy reported as left inside = 1 (F = 1 conductor)."""
    capped = RandomWalkBSDF(Microsurface("ggx", 1.0, "conductor"), walks=1, max_order=2)
    wi = direction(70)
    rng = np.random.default_rng(12)
    value, err = albedo_estimate(capped, wi, rng, 40000)
    left = capped.estimate(np.broadcast_to(wi, (4000, 3)), np.broadcast_to(direction(0), (4000, 3)),
                           rng).truncated_energy
    total = value + left.mean()
    assert 0.03 < left.mean() < 0.5
    assert abs(total - 1.0) < Z_MAX * np.hypot(err, left.std() / np.sqrt(left.size))


@pytest.mark.parametrize("kind", ["conductor", "dielectric"])
def test_sampler_follows_the_walk_and_its_pdf(kind):
    """Sampled directions: weight 1 (lossless facets), and E[g(wo)] over samples equals the
    integral of g f |cos| computed through eval (g = wo_z and wo_x)."""
    surface = Microsurface("ggx", 0.7, kind, eta=1.5)
    walk = RandomWalkBSDF(surface, walks=4)
    wi = direction(55)
    rng = np.random.default_rng(13)
    n = 6000
    wo, weight, pdf = walk.sample(np.broadcast_to(wi, (n, 3)), rng.random((n, 3)), rng)
    # pdf is approximate_pdf: deterministic and positive wherever the walk goes
    assert np.allclose(weight, 1.0) and np.all(pdf > 0)
    assert np.array_equal(pdf, walk.approximate_pdf(np.broadcast_to(wi, (n, 3)), wo))
    assert np.allclose(np.linalg.norm(wo, axis=-1), 1.0)
    ref = RandomWalkBSDF(surface, walks=1)
    for g in (lambda w: w[..., 2], lambda w: w[..., 0]):
        sampled = g(wo)
        integral, err = albedo_estimate(_Weighted(ref, g), wi, rng, 30000)
        se = np.hypot(err, sampled.std() / np.sqrt(n))
        assert abs(sampled.mean() - integral) < Z_MAX * se


@pytest.mark.parametrize("surface,theta", [
    (Microsurface("ggx", 0.7, "dielectric", eta=1.5), 45.0),
    (Microsurface("beckmann", 1.0, "dielectric", eta=1.5), 150.0),
    (Microsurface("ggx", (1.0, 0.4), "conductor"), 60.0)])
def test_approximate_pdf_is_a_density_with_the_walks_order_one(surface, theta):
    """At the share table's incidences (in the x-z plane) it integrates to 1 over the sphere:
    order 1 of the walk plus energy_loss, what order 1 misses."""
    walk = RandomWalkBSDF(surface, walks=1)
    wi = direction(theta)
    x, w = np.polynomial.legendre.leggauss(200)
    cos_t, phi = np.meshgrid(x, np.pi * (x + 1.0), indexing="ij")
    sin_t = np.sqrt(1.0 - cos_t**2)
    wo = np.stack([sin_t * np.cos(phi), sin_t * np.sin(phi), cos_t], axis=-1)
    p = walk.approximate_pdf(np.broadcast_to(wi, wo.shape), wo)
    assert np.all(p >= 0) and np.sum(np.outer(w, w) * np.pi * p) == pytest.approx(1.0, abs=2e-3)


def test_sample_walks_once_per_direction(monkeypatch):
    """Counted where the walks start: Walker.run (numpy), or sample_kernel's walk_all (compiled:
    its given first-event uniforms, one row per walk)."""
    walk = RandomWalkBSDF(Microsurface("ggx", 0.7, "dielectric", eta=1.5), walks=256)
    calls = []
    run = walk.walker.run
    walk.walker.run = lambda wi, *args, **kwargs: calls.append(len(wi)) or run(wi, *args, **kwargs)
    walk_all = sample_kernel.walk_all
    monkeypatch.setattr(sample_kernel, "walk_all", lambda *args: calls.append(len(args[7]))
                        or walk_all(*args))
    u = np.random.default_rng(1).random((1000, 3))
    walk.sample(np.broadcast_to(direction(30), (1000, 3)), u, np.random.default_rng(2))
    assert calls == [1000]


class _Weighted:
    """model.eval times g(wo), to integrate g against f |cos o| with albedo_estimate."""

    def __init__(self, model, g):
        self.model, self.g = model, g

    def eval(self, wi, wo, rng):
        return self.model.eval(wi, wo, rng) * self.g(wo)


def test_pdf_is_the_walk_density_and_eval_scales_with_fresnel():
    """For F = 1, pdf = f |cos o|; a Fresnel conductor evaluates lower, with the same pdf."""
    wi, wo = direction(40), direction(30, 150)
    mirror = RandomWalkBSDF(Microsurface("ggx", 0.6, "conductor"), walks=40000)
    gold = RandomWalkBSDF(Microsurface("ggx", 0.6, "conductor", eta_complex=0.2 + 3.0j),
                          walks=40000)
    f1 = mirror.estimate(wi, wo, np.random.default_rng(14))
    p_gold = gold.pdf(wi, wo, np.random.default_rng(14))
    assert p_gold == pytest.approx(f1.value * wo[2], rel=1e-12)  # same walks, same numbers
    assert gold.eval(wi, wo, np.random.default_rng(14)) < f1.value


def test_parent_models_forward_to_the_walk():
    glass = RoughDielectric("ggx", 0.5, 1.51, masking="correlated", multiple_scattering=True)
    wi, wo = direction(20), direction(170, 30)
    f = glass.eval(wi, wo, rng=np.random.default_rng(15))
    direct = RandomWalkBSDF(glass).eval(wi, wo, np.random.default_rng(15))
    assert f == pytest.approx(direct, rel=1e-12) and f > 0
    wo_s, weight, pdf = glass.sample(wi, np.array([0.3, 0.6, 0.2]), rng=np.random.default_rng(16))
    assert wo_s.shape == (3,) and weight == pytest.approx(1.0) and pdf > 0


def test_parent_lobes_restrict_the_walk():
    only_t = RoughDielectric("ggx", 0.8, 1.5, lobes=("transmission",), multiple_scattering=True)
    rng = np.random.default_rng(19)
    wi = direction(40)
    assert only_t.eval(wi, direction(30, 180), rng=rng) == 0.0
    assert only_t.eval(wi, direction(160, 180), rng=rng) > 0.0
    wo, weight, _ = only_t.sample(np.broadcast_to(wi, (500, 3)), rng.random((500, 3)), rng=rng)
    assert np.all(weight[wo[:, 2] > 0] == 0.0) and np.all(weight[wo[:, 2] < 0] == 1.0)


@pytest.mark.parametrize("alpha", [1e-3, 0.05, 3.0])
@pytest.mark.parametrize("theta", [0.0, 89.99, 90.0 + 1e-3, 179.0])
def test_extreme_inputs_stay_finite(alpha, theta):
    walk = RandomWalkBSDF(Microsurface("beckmann", alpha, "dielectric", eta=1.5), walks=64)
    rng = np.random.default_rng(17)
    wo = np.array([direction(t, p) for t in (0.0, 45.0, 89.9, 120.0, 179.9) for p in (0, 90)])
    f = walk.eval(np.broadcast_to(direction(theta), wo.shape), wo, rng)
    assert np.all(np.isfinite(f)) and np.all(f >= 0)
    out, weight, pdf = walk.sample(np.broadcast_to(direction(theta), (64, 3)),
                                   rng.random((64, 3)), rng)
    assert np.all(np.isfinite(out)) and np.all(np.isfinite(weight)) and np.all(pdf >= 0)


def test_energy_loss_against_an_integral_of_the_single_scattering_model():
    rng = np.random.default_rng(18)
    n = 400000
    u = rng.random((n, 2))
    z = 2 * u[:, 0] - 1
    r = np.sqrt(1 - z * z)
    wo = np.stack([r * np.cos(2 * np.pi * u[:, 1]), r * np.sin(2 * np.pi * u[:, 1]), z], -1)
    wi = direction(40)
    model = RoughConductor("ggx", 1.0, None, masking="correlated")
    terms = model.eval(wi, wo) * np.abs(z) * 4 * np.pi
    mc_loss = 1 - terms.mean()
    assert energy_loss("ggx", 1.0, None, np.radians(40)) == pytest.approx(
        mc_loss, abs=4.5 * terms.std() / np.sqrt(n))
    assert energy_loss("ggx", 1.0, 1.5, 0.0) == pytest.approx(0.107, abs=0.003)
    glass = RoughDielectric("ggx", 1.0, 1.51, masking="separable")
    terms = glass.eval(direction(85), wo) * np.abs(z) * 4 * np.pi
    assert energy_loss("ggx", 1.0, 1.51, np.radians(85), masking="separable") == pytest.approx(
        1 - terms.mean(), abs=4.5 * terms.std() / np.sqrt(n))
    assert energy_loss("beckmann", 0.05, 1.5, 0.3) < 1e-3


@pytest.mark.parametrize("kwargs,match", [
    ({"walks": 0}, "walks must be"), ({"max_order": 0}, "max_order"),
    ({"height": "exponential"}, "height must be")])
def test_bad_options_are_one_clear_error(kwargs, match):
    with pytest.raises(ValueError, match=match):
        RandomWalkBSDF(Microsurface("ggx", 0.5), **kwargs)


def test_bad_surfaces_are_one_clear_error():
    with pytest.raises(ValueError, match="kind must be one of"):
        RandomWalkBSDF(Microsurface("ggx", 0.5, "velvet"))
    with pytest.raises(ValueError, match="albedo"):
        RandomWalkBSDF(Microsurface("ggx", 0.5, "diffuse", albedo=1.5))
    with pytest.raises(ValueError, match="beckmann' or 'ggx"):
        RandomWalkBSDF(Microsurface("phong", 0.5))
    with pytest.raises(ValueError, match="order must be"):
        RandomWalkBSDF(Microsurface("ggx", 0.5)).eval(direction(0), direction(10), None, order=0)
