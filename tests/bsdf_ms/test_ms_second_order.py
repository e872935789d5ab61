"""Order 2 of the random walk by quadrature (second_order): against the walk's own order 2,
reciprocity, the analog walk's share of light leaving after exactly two events, convergence in
its node counts; and the orders >= 2 it builds (higher_orders_at) with or without covariance."""

import numpy as np
import pytest

from sim.bsdf import RoughConductor, RoughDielectric
from sim.bsdf.multiple_scattering import RandomWalkBSDF, higher_orders_at
from sim.bsdf.multiple_scattering.second_order import second_order


def _direction(theta_deg: float, phi_deg: float = 0.0) -> np.ndarray:
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])


CASES = {
    "ggx glass from above": (RoughDielectric("ggx", 0.5, 1.51, masking="correlated"),
                             _direction(30.0)),
    "beckmann glass from below": (RoughDielectric("beckmann", 0.6, 1.51, masking="correlated"),
                                  _direction(160.0)),
    "ggx gold": (RoughConductor("ggx", 0.45, eta_complex=0.2 + 3.4j, masking="correlated"),
                 _direction(45.0, 30.0)),
}
TARGETS = np.array([_direction(t, p) for t, p in
                    ((0.0, 0.0), (40.0, 180.0), (65.0, 0.0), (30.0, 70.0), (120.0, 0.0),
                     (165.0, 200.0))])


@pytest.mark.parametrize("name", CASES)
def test_quadrature_matches_the_walks_order_two(name):
    model, wi = CASES[name]
    walker = RandomWalkBSDF(model, guided=False).walker
    exact = second_order(walker, wi, TARGETS)
    rng = np.random.default_rng(11)
    walks, total, squares = 1 << 16, 0.0, 0.0
    for _ in range(walks // 8192):
        res = walker.run(np.repeat(wi[None, :], 8192, axis=0), rng, targets=TARGETS, order=2,
                         min_order=2)
        total, squares = total + res.value.sum(0), squares + (res.value ** 2).sum(0)
    mean = total / walks
    err = np.sqrt((squares / walks - mean ** 2) / walks)
    reached = err > 0
    assert np.all(exact[~reached] < 1e-6 * exact.max())  # a conductor sends nothing below
    z = (exact[reached] - mean[reached]) / err[reached]
    assert np.all(np.abs(z) < 4.5), z


def test_quadrature_is_reciprocal_in_reflection():
    """f2(wi, wo) = f2(wo, wi): the heights are integrated from wi's side only, so this checks
    their formulas independently of the walk (within the quadrature's own 0.1-0.2 %)."""
    mirror = RandomWalkBSDF(RoughConductor("ggx", 0.6, eta_complex=None,
                                           masking="correlated"), guided=False).walker
    pairs = [(_direction(10.0), _direction(50.0, 180.0)), (_direction(70.0), _direction(35.0)),
             (_direction(20.0, 40.0), _direction(80.0, 130.0))]
    for a, b in pairs:
        ab = second_order(mirror, a, b[None, :])[0] / b[2]
        ba = second_order(mirror, b, a[None, :])[0] / a[2]
        assert ab == pytest.approx(ba, rel=3e-3)


def test_integral_over_the_sphere_is_the_share_leaving_after_two_events():
    """A white mirror at alpha 1: integral of order-2 f |cos o| over wo (Gauss in cos o,
    trapezoid in azimuth) against the fraction of analog walks that leave after exactly two
    events (no next-event estimation involved)."""
    mirror = RandomWalkBSDF(RoughConductor("ggx", 1.0, eta_complex=None,
                                           masking="correlated"), guided=False).walker
    wi = _direction(40.0)
    x, w = np.polynomial.legendre.leggauss(16)
    cos_o, weight_o = 0.5 * (x + 1.0), 0.5 * w
    phi = 2.0 * np.pi * np.arange(24) / 24
    sin_o = np.sqrt(1.0 - cos_o ** 2)
    targets = np.stack([np.outer(sin_o, np.cos(phi)), np.outer(sin_o, np.sin(phi)),
                        np.outer(cos_o, np.ones_like(phi))], axis=-1).reshape(-1, 3)
    integral = np.sum(second_order(mirror, wi, targets).reshape(16, 24)
                      * weight_o[:, None] * (2.0 * np.pi / 24))
    res = mirror.run(np.repeat(wi[None, :], 1 << 17, axis=0), np.random.default_rng(4))
    share = np.mean(res.orders == 2)
    err = np.sqrt(share * (1.0 - share) / (1 << 17))
    assert abs(integral - share) < 4.5 * err + 0.005 * share, (integral, share, err)


def test_default_nodes_are_converged():
    """Within 1 % of twice the nodes (0.1-0.6 % seen: the phase functions' support edges cut
    the product rule's cells, so it converges like 1 / nodes, not spectrally)."""
    model, wi = CASES["ggx glass from above"]
    walker = RandomWalkBSDF(model, guided=False).walker
    default = second_order(walker, wi, TARGETS)
    finer = second_order(walker, wi, TARGETS, polar=256, azimuth=256, heights=12)
    np.testing.assert_allclose(default, finer, rtol=1e-2)


def test_orders_without_covariance_have_the_same_value_and_error():
    model, wi = CASES["ggx glass from above"]
    wi = np.repeat(wi[None, :], len(TARGETS), axis=0)
    with_cov = higher_orders_at(model, wi, TARGETS, 1 << 11, seed=3)
    without = higher_orders_at(model, wi, TARGETS, 1 << 11, seed=3, covariance=False)
    assert without[2] is None
    np.testing.assert_allclose(without[0], with_cov[0], rtol=1e-12)
    np.testing.assert_allclose(without[1], with_cov[1], rtol=1e-9)
    np.testing.assert_allclose(with_cov[1], np.sqrt(np.diag(with_cov[2])), rtol=1e-12)
