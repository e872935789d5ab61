"""The fit's forward model of a reading (calibration.smearing) where an edge of the lobe lies
inside the aperture: split along the model's edge circles it must follow the emulated bench's
own noiseless aperture integral (sim.bench, split the same way, asked for rtol 1e-8)."""

import numpy as np
import pytest

import calibration.smearing as smearing_module
from calibration.fit import build_model
from calibration.smearing import Smearing, model_edges, smearing_order
from gonio.geometry import directions
from sim.bench.config import build_bench

ETA = 1.51
T_EXIT = 1 - ((ETA - 1) / (ETA + 1)) ** 2  # the hemisphere's exit face at normal incidence


class _EdgesUnknown:
    """A model whose edge circles Smearing cannot know (only eval): the rim probe's path."""

    def __init__(self, model):
        self.model = model

    def eval(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        return self.model.eval(wi, wo)


def _bench_and_smearing(distribution: str, alpha: float, diameter_mm: float,
                        divergence_deg: float, kind: str = "hemisphere"):
    """The bench's noiseless reading as a BSDF (power / (|cos o| solid angle exit factor)) and
    the fit's Smearing at the orders fit() would choose, for one sample and geometry."""
    sample = {"kind": kind, "distribution": distribution, "alpha": alpha, "eta": ETA,
              "multiple_scattering": False, "diffraction": False}
    if kind == "conductor":
        sample["k"] = 3.0
    bench = build_bench({"source": {"power_w": 1.0, "divergence_deg": divergence_deg},
                         "sample": sample,
                         "aperture": {"diameter_mm": diameter_mm, "distance_mm": 500.0,
                                      "rtol": 1e-8}})
    half_angle = np.arctan(0.5 * diameter_mm / 500.0)
    omega = 4 * np.pi * np.sin(0.5 * half_angle) ** 2
    beta = float(np.degrees(half_angle))
    optics = Smearing(beta, smearing_order(beta, alpha), divergence_deg,
                      smearing_order(divergence_deg, alpha))

    def reading(theta_i: float, arm: float) -> float:
        _, wo = directions(theta_i, arm)
        exit_factor = T_EXIT if wo[2] < 0 else 1.0  # transmission leaves through the dome
        power = bench.power_w({"sample": theta_i, "arm": arm, "azimuth": 0.0, "elevation": 0.0})
        return power / (abs(wo[2]) * omega * exit_factor)

    return reading, optics


@pytest.mark.parametrize("distribution, alpha, theta_i, arms, divergence_deg, old_off", [
    # GGX's vertical-facet jump at the end of the transmitted lobe (theta_o ~ 55.5 deg)
    ("ggx", 0.394, 30.0, np.arange(153.75, 156.3, 0.25), 0.03, True),
    # at normal incidence the end of the lobe and the vertical facets are one circle (48.5
    # deg), where GGX's jump D(90 deg) i.m vanishes: a kink only, which the old rule resolved
    ("ggx", 0.553, 0.0, np.arange(227.0, 230.1, 0.25), 0.03, False),
    # the same jump at 60 deg incidence for a smoother sample, collimated beam
    ("ggx", 0.2, 60.0, np.arange(168.5, 171.1, 0.25), 0.0, True),
])
def test_split_smearing_follows_the_bench_across_a_lobe_edge(distribution, alpha, theta_i, arms,
                                                             divergence_deg, old_off):
    reading, optics = _bench_and_smearing(distribution, alpha, 10.0, divergence_deg)
    model = build_model(distribution, alpha, ETA, "separable")
    pairs = [directions(theta_i, arm) for arm in arms]
    wi, wo = np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs])
    bench = np.array([reading(theta_i, arm) for arm in arms])
    fitted = optics.average(model, wi, wo)
    scan = [directions(theta_i, arm) for arm in np.arange(120.0, 240.0, 0.5)]
    scan_wo = np.array([p[1] for p in scan])
    peak = model.eval(np.array([p[0] for p in scan]), scan_wo)[scan_wo[:, 2] < 0].max()
    assert np.sum((bench > 0) & (bench < 0.9 * bench.max())) >= 2  # the apertures cross the edge
    assert fitted == pytest.approx(bench, rel=1e-5, abs=1e-6 * peak)
    # before the split (the rim probe and the top polar order, still used for models whose
    # edges are unknown) the two differed by ~1e-3 of the largest value in the scan
    old = optics.average(_EdgesUnknown(model), wi, wo)
    assert (np.max(np.abs(old - bench)) > 3e-4 * bench.max()) == old_off


def test_split_smearing_follows_the_bench_across_the_horizon():
    # A conductor's reflected lobe cut by the horizon (grazing exit, theta_i 70 deg): the
    # aperture straddles the z = 0 circle, where f |cos o| falls to zero.
    reading, optics = _bench_and_smearing("ggx", 0.3, 20.0, 0.0, kind="conductor")
    model = build_model("ggx", 0.3, ETA, "separable", k=3.0)
    arms = np.array([159.2, 159.5, 159.8])  # theta_o = 90 - 0.8 ... 90 - 0.2 deg
    pairs = [directions(70.0, arm) for arm in arms]
    wi, wo = np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs])
    bench = np.array([reading(70.0, arm) for arm in arms])
    assert np.all(np.abs(90.0 - np.degrees(np.arccos(wo[:, 2]))) < np.degrees(np.arctan(0.02)))
    assert optics.average(model, wi, wo) == pytest.approx(bench, rel=1e-5)


def test_model_edges_come_from_the_candidate():
    # The edges move with the fitted eta (the vertical-facet circle's level is -cos i / eta).
    wi = np.array([[0.0, 0.0, 1.0]])
    for eta in (1.3, 1.51, 1.9):
        z_family = model_edges(build_model("ggx", 0.3, eta, "separable")).circles(wi)[0]
        assert z_family[1][0, -1] == pytest.approx(-1.0 / eta)
    conductor = model_edges(build_model("ggx", 0.3, 1.5, "separable", k=3.0))
    assert not conductor.transmits
    assert model_edges(_EdgesUnknown(None)) is None


def test_unknown_edges_get_the_top_order_where_the_rim_finds_an_edge(monkeypatch):
    # GGX transmission at 30 deg incidence ends in a jump to zero near theta_o 55.5 deg. For a
    # model whose edges Smearing cannot know, an edge found on the rule's nodes or on the rim
    # gets the top order (EDGE_ORDER): within 5 % of each value and 1e-3 of the peak of a
    # 150-ring reference (convergence across a jump is only algebraic), where the low order
    # alone is off by more than 2 % of the peak.
    model = _EdgesUnknown(build_model("ggx", 0.394, ETA, "separable"))
    half_angle = np.degrees(np.arctan(0.01))
    pairs = [directions(30.0, arm) for arm in np.arange(153.5, 156.0, 0.125)]
    wi, wo = np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs])
    fitted = Smearing(half_angle, 3, 0.0, 0).average(model, wi, wo)
    monkeypatch.setattr(smearing_module, "EDGE_ORDER", 3)
    plain = Smearing(half_angle, 3, 0.0, 0).average(model, wi, wo)
    monkeypatch.setattr(smearing_module, "EDGE_ORDER", 150)
    reference = Smearing(half_angle, 150, 0.0, 0).average(model, wi, wo)
    peak = reference.max()
    assert np.sum((reference > 0) & (reference < 0.9 * peak)) >= 3  # the scan crosses the edge
    assert np.max(np.abs(plain - reference)) > 0.02 * peak
    assert fitted == pytest.approx(reference, rel=0.05, abs=1e-3 * peak)


@pytest.mark.parametrize("known_edges", [True, False])
def test_one_call_over_many_points_gives_each_point_its_own_value(known_edges):
    # A call evaluates one plan of node pairs for all its points (split, top-order and product
    # rules merged, kept per pair set): each point must get the value it gets alone, in any
    # order of the points, on a second call too. Points across GGX's transmitted-lobe edge at
    # 30 deg, in the lobe and in reflection. About 0.5 s of CPU.
    model = build_model("ggx", 0.394, ETA, "separable")
    model = model if known_edges else _EdgesUnknown(model)
    optics = Smearing(np.degrees(np.arctan(0.01)), 3, 0.03, 1)
    arms = np.concatenate([np.arange(153.5, 156.0, 0.5), [170.0, 190.0, 60.0, 30.0]])
    pairs = [directions(30.0, arm) for arm in arms]
    wi, wo = np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs])
    together = optics.average(model, wi, wo)
    alone = np.array([optics.average(model, wi[k:k + 1], wo[k:k + 1])[0]
                      for k in range(len(wi))])
    assert np.sum((together > 0) & (together < 0.9 * together[:5].max())) >= 2  # the edge
    assert np.all(together[5:] > 0)
    assert together == pytest.approx(alone, rel=1e-13, abs=0.0)
    assert optics.average(model, wi[::-1], wo[::-1]) == pytest.approx(together[::-1],
                                                                       rel=1e-13, abs=0.0)
    assert np.array_equal(optics.average(model, wi, wo), together)
