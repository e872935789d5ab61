"""Orders >= 2 by shared-path next-event estimation (HigherOrderLobe, higher_orders_at): the
compiled kernel against the numpy reference, agreement with the per-pair random walk (all
orders minus order 1), energy against energy_loss, reciprocity, interpolation, determinism."""

import math

import numpy as np
import pytest

from model.bsdf import RoughConductor, RoughDielectric
from model.bsdf.distributions import WALKABLE, make_distribution
from model.bsdf.multiple_scattering import (
    HigherOrderLobe,
    RandomWalkBSDF,
    energy_loss,
    higher_orders_at,
    nee_kernel,
)
from model.bsdf.multiple_scattering.micro import MicroConductor, MicroDielectric
from model.bsdf.multiple_scattering.second_order import second_order
from model.bsdf.multiple_scattering.walk import Walker

Z_MAX = 4.5  # |z-score| allowed for a Monte Carlo comparison (deterministic seeds)
GLASS = RoughDielectric("ggx", 0.5, 1.51, masking="correlated")


def direction(theta_deg, phi_deg=0.0):
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])


@pytest.mark.skipif(not nee_kernel.AVAILABLE, reason="numba is not installed")
@pytest.mark.parametrize("name", WALKABLE)
@pytest.mark.parametrize("micro", [MicroDielectric(1.51), MicroDielectric(1.0 / 1.51),
                                   MicroConductor(None), MicroConductor(0.2 + 3.4j)],
                         ids=["glass", "inverse-glass", "mirror", "gold-like"])
def test_compiled_next_event_matches_numpy(name, micro):
    rng = np.random.default_rng(1)
    walker = Walker(make_distribution(name, 0.4), micro, guided=False)
    n, m = 400, 60
    w_in = rng.normal(size=(n, 3))
    w_in /= np.linalg.norm(w_in, axis=1, keepdims=True)
    targets = rng.normal(size=(m, 3))
    targets /= np.linalg.norm(targets, axis=1, keepdims=True)
    targets[:3] = [[0.0, 0.0, 1.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]]  # poles, horizon
    out = rng.random(n) < 0.5
    here = np.log(rng.random(n))
    there = np.log1p(-np.exp(here))
    args = (w_in, w_in, out, targets, here, there, False)
    fast = walker.next_event_all(*args, compiled=True)
    slow = walker.next_event_all(*args, compiled=False)
    assert np.all(np.isfinite(fast)) and np.count_nonzero(slow) > 0.2 * slow.size
    np.testing.assert_allclose(fast, slow, rtol=1e-6, atol=1e-300)


@pytest.mark.parametrize("wi,wo", [
    (direction(30), direction(50, 160)),  # reflection
    (direction(30), direction(160, 170)),  # transmission
    (direction(60), direction(130, 20)),  # transmission, out of plane
    (-direction(20), -direction(40, 180)),  # transmission from the glass
])
def test_orders_two_and_up_match_the_per_pair_walk(wi, wo):
    """Shared-path NEE (min_order 2) against the guided per-pair walk's all orders minus order
    1 (walked from the same seed, so order 1 cancels exactly): the same expectation."""
    value, err, _ = (float(v.ravel()[0]) for v in higher_orders_at(GLASS, wi, wo, 1 << 15, 2))
    walk = RandomWalkBSDF(GLASS, walks=1 << 13)
    every = walk.estimate(wi, wo, np.random.default_rng(3))
    first = walk.estimate(wi, wo, np.random.default_rng(3), order=1)
    reference = every.value - first.value
    assert value > 0 and err < 0.2 * value
    assert abs(value - reference) < Z_MAX * math.hypot(err, float(every.stderr))


@pytest.mark.parametrize("model,theta", [
    (GLASS, 30.0), (RoughDielectric("beckmann", 0.7, 1.51, masking="correlated"), 60.0),
    (RoughConductor("ggx", 0.8, None, masking="correlated"), 45.0)])
def test_table_energy_is_what_single_scattering_loses(model, theta):
    """The integral of the tabulated lobe times |cos o| over the sphere (trapezoid rule on the
    grid, both azimuth halves) equals energy_loss, an independent quadrature of order 1, within
    the tables' Monte Carlo error (taken as fully correlated within a column) and 1 % for the
    5-degree trapezoid rule."""
    lobe = HigherOrderLobe(model, walks=1 << 12, seed=4)
    node = int(theta / 5.0)
    t, p = np.radians(lobe.polar_deg), np.radians(lobe.phi_deg)
    split = len(lobe.upper_deg)
    columns = [lobe.column(1, node, j) for j in range(len(p))]
    f, err = (np.stack([c[0] + c[1] for c in columns], axis=1),
              np.stack([c[2] for c in columns], axis=1))
    weight = np.abs(np.cos(t))[:, None] * np.sin(t)[:, None]
    trapezoid_t = np.zeros(len(t))  # the trapezoid rule on each hemisphere's nodes
    for half in (slice(0, split), slice(split, None)):
        step = np.diff(t[half])
        trapezoid_t[half] = np.concatenate([[0.5 * step[0]], 0.5 * (step[:-1] + step[1:]),
                                            [0.5 * step[-1]]])
    trapezoid_p = np.full(len(p), p[1] - p[0])
    trapezoid_p[[0, -1]] *= 0.5
    cell = 2.0 * weight * trapezoid_t[:, None] * trapezoid_p[None, :]
    energy = float(np.sum(f * cell))
    energy_err = float(np.sqrt(np.sum(np.sum(err * cell, axis=0) ** 2)))
    eta = getattr(model, "eta", None)
    loss = energy_loss(model.distribution.name, 0.0 + model.distribution.alpha_x, eta,
                       math.radians(theta))
    assert loss > 0.02 and energy_err < 0.1 * loss
    assert abs(energy - loss) < Z_MAX * energy_err + 0.01 * loss, (energy, energy_err, loss)


def test_reflection_is_reciprocal():
    """f(wi, wo) = f(wo, wi) for the reflected orders >= 2, each from its own table."""
    lobe = HigherOrderLobe(GLASS, walks=1 << 14, seed=5)
    pairs = [(30.0, 60.0, 180.0), (20.0, 45.0, 90.0), (0.0, 70.0, 0.0)]
    for a, b, phi in pairs:
        forward, e1 = lobe.estimate(direction(a), direction(b, phi))
        backward, e2 = lobe.estimate(direction(b), direction(a, phi))
        assert abs(forward - backward) < Z_MAX * math.hypot(e1, e2) + 1e-12


def test_interpolation_between_nodes_agrees_with_walks_at_the_pairs():
    """Off the grid (incidence 32 deg, polar and azimuth between nodes) the interpolated lobe
    agrees with the lobe walked at the pairs within the errors plus 3 % of the lobe's peak."""
    lobe = HigherOrderLobe(GLASS, walks=1 << 14, seed=6)
    wi = direction(32.0)
    wo = np.array([direction(t, p) for t, p in ((12.0, 37.0), (52.0, 170.0), (71.0, 95.0),
                                                (133.0, 8.0), (167.0, 120.0), (118.0, 175.0))])
    table, table_err = lobe.estimate(wi, wo)
    walked, walked_err, _ = higher_orders_at(GLASS, wi, wo, 1 << 15, seed=7)
    peak = walked.max()
    assert np.all(np.abs(table - walked) < Z_MAX * np.hypot(table_err, walked_err) + 0.03 * peak)


def test_order_two_interpolates_the_quadrature():
    """Order 2, tabulated apart from the walked orders (walks=2 leave those noise), follows
    second_order at in-plane pairs off the nodes at 60 deg incidence, where linear steps of 2.5
    deg were off by rms 3 %: cubic in theta_o within rms 1 % (what is left is mostly the
    quadrature's own unevenness: rms 0.4 % at 60 deg with the compiled rule), and within
    10 % in the last degree above and below the horizon (linear to a 0 on it: 20-80 %). Cost:
    two builds and a quadrature at 36 pairs, ~1 s."""
    lobe = HigherOrderLobe(GLASS, walks=2, seed=0)
    wi = direction(60.0)
    rng = np.random.default_rng(8)
    theta = np.concatenate([rng.uniform(1.0, 87.0, 14), rng.uniform(93.0, 179.0, 14),
                            [88.3, 89.0, 89.7, 90.3, 90.7, 91.2, 92.0, 92.4]])
    azimuth = rng.choice([0.0, 180.0], len(theta))
    wo = np.array([direction(t, phi) for t, phi in zip(theta, azimuth, strict=True)])
    reference = second_order(lobe.walk.walker, wi, wo) / np.abs(wo[:, 2])
    second, higher, _ = lobe.parts(wi, wo)
    error = second / reference - 1.0
    assert np.sqrt(np.mean(error[:28] ** 2)) < 0.01 and np.max(np.abs(error[28:])) < 0.1
    # the order-2 tables are the quadrature's: the seed changes only the walked orders
    other = HigherOrderLobe(GLASS, walks=2, seed=1).parts(wi, wo)
    np.testing.assert_array_equal(other[0], second)
    assert not np.array_equal(other[1], higher)


def test_one_walk_set_builds_both_azimuths_of_a_plane():
    """Columns 0 and 180 deg of one hemisphere are one build (one walk set, one quadrature):
    at the pole, where they meet, the two agree to rounding, where separate walk sets would
    differ by their Monte Carlo error. Cost: two builds of 4096 walks, ~0.5 s."""
    lobe = HigherOrderLobe(GLASS, walks=1 << 12, seed=3)
    lobe.eval(direction(30.0), np.array([direction(150.0, 0.0), direction(150.0, 180.0)]))
    assert lobe.planes_built == 1
    near, far = lobe.column(1, 6, 0), lobe.column(1, 6, len(lobe.phi_deg) - 1)
    assert lobe.planes_built == 2  # and the upper hemisphere of that plane
    for pole in (0, -1):
        assert near[1][pole] > 0.0 and near[2][pole] > 1e-3 * near[1][pole]
        np.testing.assert_allclose([near[0][pole], near[1][pole]],
                                   [far[0][pole], far[1][pole]], rtol=1e-6)


def test_tables_are_deterministic_and_walk_only_the_columns_needed():
    wi = direction(30.0)
    wo = np.array([direction(150.0, 0.3), direction(170.0, 179.5), direction(40.0, 180.0)])
    a = HigherOrderLobe(GLASS, walks=512, seed=1)
    b = HigherOrderLobe(GLASS, walks=512, seed=1)
    np.testing.assert_array_equal(a.eval(wi, wo), b.eval(wi, wo))
    # transmitted at 0 and 180 deg azimuth (one plane: one build), reflected at 180 deg
    assert a.planes_built == 2
    normal = HigherOrderLobe(GLASS, walks=512, seed=1)
    normal.eval(direction(0.0), np.array([direction(150.0, phi) for phi in (0, 40, 99, 180)]))
    assert normal.planes_built == 1  # at normal incidence one azimuth serves all
    # a divergent beam's directions 0.03 deg off a node walk no neighbouring incidence
    normal.eval(direction(0.03, 77.0), np.array([direction(150.0, phi) for phi in (0, 99)]))
    assert normal.planes_built == 1
    assert not np.array_equal(a.eval(wi, wo), HigherOrderLobe(GLASS, walks=512, seed=2).eval(
        wi, wo))


@pytest.mark.parametrize("kwargs,match", [
    ({"walks": 1}, "walks"), ({"walks": 2.5}, "walks"),
    ({"theta_step_deg": 7.0}, "theta_step_deg"), ({"phi_step_deg": 0.0}, "phi_step_deg")])
def test_bad_settings_are_refused(kwargs, match):
    with pytest.raises(ValueError, match=match):
        HigherOrderLobe(GLASS, **kwargs)


def test_anisotropic_surfaces_are_refused():
    with pytest.raises(ValueError, match="isotropic"):
        HigherOrderLobe(RoughDielectric("ggx", (0.5, 0.2), 1.51, masking="correlated"))


def test_every_azimuth_at_normal_incidence_is_column_zero():
    """At normal incidence the lobe does not depend on the azimuth: one build of column 0
    serves every column asked for (the far columns were left unwritten, all zeros). ~0.2 s."""
    lobe = HigherOrderLobe(GLASS, walks=1 << 8, seed=2)
    first, last = lobe.column(1, 0, 0), lobe.column(1, 0, len(lobe.phi_deg) - 1)
    assert first[0].max() > 0.0
    for a, b in zip(first, last, strict=True):
        np.testing.assert_array_equal(a, b)


def test_pairs_the_lobe_cannot_tell_apart_are_walked_once():
    """higher_orders_at gives the same value, error and covariance row to pairs an isotropic
    lobe cannot tell apart (mirror images about the plane of incidence; at normal incidence any
    azimuth), and its walk from the same seed then scores only the distinct ones, so a point
    added at a mirror azimuth leaves the other points' values as they were."""
    normal = np.array([0.0, 0.0, 1.0])
    oblique = direction(40.0, 25.0)
    for wi, wo in ((normal, [direction(35.0, p) for p in (0.0, 90.0, 180.0, 300.0)]),
                   (oblique, [direction(35.0, 25.0 + d) for d in (60.0, -60.0)])):
        wo = np.array(wo)
        value, err, cov = higher_orders_at(GLASS, wi, wo, 1 << 12, seed=5)
        assert value[0] > 0 and np.all(value == value[0]) and np.all(err == err[0])
        assert np.all(cov == cov[0, 0])  # one estimate: fully correlated
        alone, alone_err, _ = higher_orders_at(GLASS, wi, wo[:1], 1 << 12, seed=5)
        assert alone[0] == value[0] and alone_err[0] == err[0]
    distinct, _, _ = higher_orders_at(GLASS, normal, np.array([direction(35.0),
                                                                direction(150.0)]), 1 << 12, 5)
    mirrored, _, _ = higher_orders_at(GLASS, normal, np.array([direction(35.0),
                                                                direction(150.0, 180.0),
                                                                direction(35.0, 180.0)]),
                                      1 << 12, 5)
    assert np.array_equal(mirrored, distinct[[0, 1, 0]])
