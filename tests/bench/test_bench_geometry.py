"""sim.bench.geometry against the cases of docs/architecture.md and against gonio.geometry."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sim.bench.geometry import (
    angle_from_beam_rad,
    lab_to_sample,
    sample_frame_directions,
    sample_to_lab,
)

angles = st.floats(-180.0, 180.0, allow_nan=False)


@pytest.mark.parametrize("s, a", [(0.0, 30.0), (30.0, 60.0), (-45.0, 100.0), (75.0, 200.0)])
def test_in_plane_cases_of_architecture_md(s, a):
    wi, wo = sample_frame_directions({"sample": s, "arm": a})
    rs, rd = np.radians(s), np.radians(a - s)
    assert wi == pytest.approx([-np.sin(rs), 0.0, np.cos(rs)], abs=1e-15)
    assert wo == pytest.approx([np.sin(rd), 0.0, np.cos(rd)], abs=1e-15)


def test_specular_straight_through_and_transmitted_side():
    wi, wo = sample_frame_directions({"sample": 30.0, "arm": 60.0})
    assert wo == pytest.approx(wi * [-1, -1, 1], abs=1e-15)  # mirror direction
    wi, wo = sample_frame_directions({"sample": 30.0, "arm": 180.0})
    assert wo == pytest.approx(-wi, abs=1e-15)  # the straight beam
    assert sample_frame_directions({"sample": 10.0, "arm": 120.0})[1][2] < 0  # |a - s| > 90


def test_elevation_and_azimuth():
    wi, wo = sample_frame_directions({"sample": 0.0, "arm": 180.0, "elevation": 20.0})
    assert wo[1] == pytest.approx(np.sin(np.radians(20.0)))
    wi, wo = sample_frame_directions({"sample": 30.0, "arm": 60.0, "azimuth": 90.0})
    # turning the sample by 90 deg about its normal moves the plane of incidence to x' = 0
    assert wi[0] == pytest.approx(0.0, abs=1e-15) and wi[1] == pytest.approx(0.5)


def test_flipped_mount_lights_the_interior_side():
    wi, wo = sample_frame_directions({"sample": 0.0, "arm": 180.0}, flipped=True)
    assert wi == pytest.approx([0, 0, -1]) and wo == pytest.approx([0, 0, 1])


@settings(max_examples=200, deadline=None)
@given(angles, angles, angles, angles, st.booleans())
def test_agrees_with_gonio_geometry_and_round_trips(s, a, e, p, flipped):
    from gonio.geometry import directions

    e = e / 2.0  # elevation within +-90
    wi, wo = sample_frame_directions({"sample": s, "arm": a, "elevation": e, "azimuth": p})
    gi, go = directions(s, a, e, p)
    assert np.allclose(wi, gi, atol=1e-12) and np.allclose(wo, go, atol=1e-12)
    v = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    back = sample_to_lab(lab_to_sample(v, s, p, flipped), s, p, flipped)
    assert np.allclose(back, v, atol=1e-12)


def test_angle_from_beam_is_accurate_for_tiny_offsets():
    assert angle_from_beam_rad(180.0 - 1e-7) == pytest.approx(np.radians(1e-7), rel=1e-6)
    assert angle_from_beam_rad(0.0) == pytest.approx(np.pi)


def test_one_reading_is_the_vectorised_result_bit_for_bit():
    """A reading's directions (numbers in, the path the emulated detector takes) are the rows
    of the vectorised call exactly, either mount."""
    rng = np.random.default_rng(5)
    poses = {role: rng.uniform(-180.0, 180.0, 300) for role in ("sample", "arm", "azimuth")}
    poses["elevation"] = rng.uniform(-60.0, 60.0, 300)
    poses["sample"][:4] = [0.0, -0.0, 90.0, 180.0]
    for flipped in (False, True):
        wi, wo = sample_frame_directions(poses, flipped=flipped)
        for k in range(300):
            one = sample_frame_directions({r: float(v[k]) for r, v in poses.items()}, flipped)
            assert one[0].tobytes() == wi[k].tobytes() and one[1].tobytes() == wo[k].tobytes()
