"""The bench's instrument scatter ([sim.stray]): the halo holds its stated fraction of the beam
over the sphere (by quadrature in arm and elevation, another parametrisation than the code's),
its aperture integral matches a fine cap rule, it is off by default, it adds alike with the
sample in the beam and retracted, and every bad key is one clear error."""

import math

import numpy as np
import pytest

from model.optics.quadrature import cap_rule
from sim.bench import build_bench
from sim.bench.geometry import BEAM_DIRECTION, angle_from_beam_rad, detector_direction
from sim.bench.stray import InstrumentScatter
from sim.devices.photodiode import SimConfigError

HALOS = [(1.0, 3.0), (0.1, 1.0), (30.0, 6.0), (2.0, 2.0)]  # (width deg, slope)


@pytest.mark.parametrize("width, slope", HALOS)
def test_the_halo_integrates_to_its_fraction_over_the_sphere(width, slope):
    """A tensor Gauss-Legendre rule in arm and elevation (d omega = cos e da de), on panels
    that shrink geometrically towards the beam axis (arm 180, elevation 0)."""
    halo = InstrumentScatter(halo_fraction=1e-3, halo_width_deg=width, halo_slope=slope)
    x, w = np.polynomial.legendre.leggauss(16)

    def nodes(reach):
        steps = width * 2.0 ** np.arange(-6.0, 12.0)
        edges = np.unique(np.concatenate([[0.0], steps[steps < reach], [reach]]))
        edges = np.concatenate([-edges[::-1], edges[1:]])
        half = 0.5 * np.diff(edges)[:, None]
        return ((0.5 * (edges[1:] + edges[:-1]))[:, None] + half * x).ravel(), \
            (half * w).ravel()

    arm, w_arm = nodes(180.0)
    elevation, w_elevation = nodes(90.0)
    a, e = np.meshgrid(180.0 + arm, elevation, indexing="ij")
    density = halo.halo_per_sr(angle_from_beam_rad(a, e)) * np.cos(np.radians(e))
    total = float(w_arm @ density @ w_elevation) * (math.pi / 180.0) ** 2
    assert total == pytest.approx(1e-3, rel=1e-8)


@pytest.mark.parametrize("width", [0.1, 0.5, 3.0])
@pytest.mark.parametrize("off_deg", [0.0, 0.05, 0.3, 0.57, 3.0, 20.0])
@pytest.mark.parametrize("aperture_deg", [math.degrees(math.atan(0.01)), 3.0])
def test_the_aperture_integral_matches_a_fine_cap_rule(width, off_deg, aperture_deg):
    halo = InstrumentScatter(halo_fraction=1e-3, halo_width_deg=width)
    beta = math.radians(aperture_deg)
    nodes, weights = cap_rule(detector_direction(180.0 + off_deg, 0.0), beta, 200)
    gamma = np.arctan2(np.linalg.norm(np.cross(nodes, BEAM_DIRECTION), axis=-1),
                       nodes @ BEAM_DIRECTION)
    reference = float(weights @ halo.halo_per_sr(gamma))
    assert halo.fraction(180.0 + off_deg, 0.0, beta) == pytest.approx(reference, rel=1e-5)
    # out of plane the same angle from the beam gives the same power
    assert halo.fraction(180.0, off_deg, beta) == pytest.approx(reference, rel=1e-5)


def test_off_by_default_and_alike_with_the_sample_in_and_out():
    plain = build_bench({})
    assert plain.stray == InstrumentScatter()
    stray = {"halo_fraction": 1e-3, "halo_width_deg": 1.0, "arm_fraction": 1e-6,
             "arm_variation": 0.5}
    bench = build_bench({"stray": stray})
    ap = bench.integral.aperture_rad
    for sample, arm in ((0.0, 185.0), (90.0, 185.0), (20.0, 140.0), (90.0, 90.0)):
        pos = {"sample": sample, "arm": arm}
        added = bench.power_w(pos) - plain.power_w(pos)
        expected = bench.source.power_at(0.0) * bench.stray.fraction(arm, 0.0, ap)
        assert added == pytest.approx(expected, rel=1e-9)
        assert expected >= 1e-3 * 0.5e-6  # the arm's stray light at least
    halo_only = InstrumentScatter(halo_fraction=1e-3, halo_width_deg=1.0)
    assert halo_only.fraction(185.0, 0.0, ap) > 100 * halo_only.fraction(140.0, 0.0, ap)


@pytest.mark.parametrize("table, message", [
    ({"halo_fraction": -1e-3}, "[sim.stray] halo_fraction: must be a number >= 0"),
    ({"halo_fraction": 0.5}, "[sim.stray] halo_fraction: must be a number >= 0 and <= 0.1"),
    ({"halo_width_deg": 0.0}, "[sim.stray] halo_width_deg: must be a number >= 0.1"),
    ({"halo_slope": "steep"}, "[sim.stray] halo_slope: must be a number"),
    ({"arm_fraction": 1.0}, "[sim.stray] arm_fraction: must be a number >= 0 and <= 0.01"),
    ({"arm_variation": 2.0}, "[sim.stray] arm_variation: must be a number >= 0 and <= 1"),
    ({"halo": 1e-3}, "[sim.stray]: unknown key 'halo'"),
])
def test_bad_stray_keys_are_one_clear_error(table, message):
    with pytest.raises(SimConfigError) as err:
        build_bench({"stray": table})
    assert message in str(err.value) and "\n" not in str(err.value)
