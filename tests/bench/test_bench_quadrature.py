"""Cap quadrature and the order rule against closed forms and scipy's adaptive quadrature."""

import math

import numpy as np
import pytest
from scipy import integrate

from model.optics.aperture import MAX_ORDER, ApertureIntegral, LobeScales, order_for
from model.optics.quadrature import cap_rule, cap_solid_angle, node_count

Z = np.array([0.0, 0.0, 1.0])


def gaussian(peak, width):
    def g(w):
        return np.exp(-np.arccos(np.clip(w @ peak, -1, 1)) ** 2 / (2 * width**2))
    return g


def cap_integral(g, beta, n):
    nodes, weights = cap_rule(Z, beta, n)
    return float(g(nodes) @ weights)


def direction(theta, phi=0.3):
    return np.array([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])


@pytest.mark.parametrize("beta", [1e-4, 0.01, 0.3, 1.2])
def test_weights_sum_to_the_solid_angle(beta):
    for n in (0, 12):
        assert cap_rule(Z, beta, n)[1].sum() == pytest.approx(cap_solid_angle(beta), rel=1e-12)
    assert cap_solid_angle(beta) == pytest.approx(2 * math.pi * (1 - math.cos(beta)), rel=1e-9)


def test_nodes_are_unit_and_inside_the_cap_for_any_centre():
    c = np.array([0.6, -0.0, -0.8])
    nodes, _ = cap_rule(c, 0.2, 6)
    assert nodes.shape == (node_count(6), 3)
    assert np.allclose(np.linalg.norm(nodes, axis=-1), 1.0)
    assert np.all(nodes @ c >= math.cos(0.2) - 1e-12)


@pytest.mark.parametrize("offset", [0.0, 0.004, 0.012])
def test_off_centre_gaussian_against_scipy_dblquad(offset):
    beta, width = 0.01, 0.004
    g = gaussian(direction(offset), width)

    def polar(rho, phi):
        return g(direction(rho, phi)) * math.sin(rho)

    ref, _ = integrate.dblquad(polar, 0, 2 * math.pi, 0, beta, epsabs=0, epsrel=1e-11)
    assert cap_integral(g, beta, 12) == pytest.approx(ref, rel=1e-8)


def test_order_rule_meets_its_accuracy_on_gaussian_lobes_at_any_offset():
    """The local scale of a Gaussian lobe of width w at distance r is w^2 / (w + r)."""
    rng = np.random.default_rng(2)
    beta = math.radians(0.6)
    for rtol in (1e-2, 1e-3, 1e-5):
        worst = 0.0
        for _ in range(150):
            w = beta / 10 ** rng.uniform(-1.3, 1.0)
            r = rng.uniform(0, 4) * max(beta, w)
            g = gaussian(direction(r, rng.uniform(0, 2 * math.pi)), w)
            n = order_for(beta * (w + r) / w**2, rtol)
            worst = max(worst, abs(cap_integral(g, beta, n) / cap_integral(g, beta, 48) - 1))
        assert worst < rtol, (rtol, worst)


def test_one_point_only_when_accurate():
    assert order_for(0.01, 1e-3) == 0 and order_for(0.05, 1e-3) > 0
    ap = ApertureIntegral(math.radians(0.5), 0.0, 1e-3)
    assert ap.orders(LobeScales(1.0, 1.0, 1.0, 1.0)) == (0, 0)  # a radian-wide lobe: one point
    assert ap.orders(LobeScales(1.0, math.radians(0.5), 1.0, 1.0))[1] >= 3
    # an edge (kink) inside the cap: the rule converges slowly there, so the top order
    assert ap.orders(LobeScales(1.0, 1.0, 1.0, math.radians(0.2)))[1] == MAX_ORDER


def test_divergence_average_of_a_constant_is_exact():
    ap = ApertureIntegral(0.01, 0.005, 1e-3, order=(5, 5))
    value = ap.integrate(lambda wi, wo: np.ones(np.broadcast_shapes(wi.shape, wo.shape)[:-1]),
                         Z, -Z, LobeScales(1.0, 1.0, 1.0, 1.0))
    assert value == pytest.approx(cap_solid_angle(0.01), rel=1e-12)


@pytest.mark.parametrize("kwargs", [{"aperture_rad": 0.0}, {"aperture_rad": 0.1, "rtol": 0.0},
                                    {"aperture_rad": 0.1, "divergence_rad": -1.0}])
def test_bad_aperture_parameters(kwargs):
    with pytest.raises(ValueError):
        ApertureIntegral(**kwargs)


def test_an_edge_inside_the_aperture_does_not_also_max_out_the_beam_rule():
    """A lobe edge inside the aperture gets the aperture's highest order; the beam cone then
    averages an integral the aperture has already smoothed, so its order follows the lobe and
    the aperture (the product of two maximal rules was 10.7 M evaluations per reading)."""
    integral = ApertureIntegral(math.radians(0.57), math.radians(0.03))
    edge_in_both = LobeScales(0.3, 0.3, 1e-6, 1e-6)
    n_i, n_o = integral.orders(edge_in_both)
    assert n_o == MAX_ORDER and n_i < 8
    assert node_count(n_i) * node_count(n_o) < 1e5
    edge_in_beam_only = LobeScales(0.3, 0.3, 1e-6, 1.0)
    assert integral.orders(edge_in_beam_only)[0] == MAX_ORDER


def test_a_reading_across_the_transmitted_lobes_edge_agrees_with_a_fine_rule():
    """Walter's ground glass at 30 deg incidence, the arm where the transmitted lobe ends: the
    automatic rule (split along the edge) against the split rule at 4 x 32, within rtol 1e-3
    (the polar rule's top order reached only 5e-3 here; tests/bench/test_aperture_split.py
    checks such readings against quasi-Monte Carlo)."""
    from dataclasses import replace

    from sim.bench import build_bench
    from sim.bench.geometry import sample_frame_directions

    bench = build_bench({"source": {"divergence_deg": 0.03}, "sample": {
        "kind": "hemisphere", "distribution": "ggx", "alpha": 0.394, "eta": 1.51,
        "multiple_scattering": False}})
    pos = {"sample": 30.0, "arm": 155.0}
    wi, wo = sample_frame_directions(pos, flipped=bench.sample.flipped)
    scales = bench.sample.lobe_scales(wi, wo)
    assert scales.edge_o < bench.integral.aperture_rad  # the edge is inside the aperture
    fine = replace(bench.integral, order=(4, 32)).integrate(bench.sample.integrand, wi, wo,
                                                             scales)
    assert bench.scattered_fraction(pos) == pytest.approx(fine, rel=1e-3)
