"""gonio.geometry against the architecture convention, the closed in-plane forms, and the
independent implementation in sim.bench.geometry."""

import numpy as np
from hypothesis import example, given, settings
from hypothesis import strategies as st

from gonio.geometry import directions, into_limits, sample_angles, stage_angles, wrap_deg
from sim.bench.geometry import sample_frame_directions

angle = st.floats(-180.0, 180.0, allow_nan=False)


def test_in_plane_closed_forms():
    s = np.array([0.0, 10.0, 30.0, 60.0, 85.0])
    spec = stage_angles(s, s)  # reflection: theta_o = theta_i forward is the specular
    np.testing.assert_allclose(spec.arm_deg, 2 * s, atol=1e-12)
    straight = stage_angles(s, s, transmission=True)  # continuing the incident ray
    np.testing.assert_allclose(np.abs(straight.arm_deg), 180.0, atol=1e-12)
    normal_t = stage_angles(s, 0.0, transmission=True)  # along -n
    np.testing.assert_allclose(wrap_deg(normal_t.arm_deg - s), 180.0, atol=1e-12)
    back = stage_angles(30.0, -30.0)  # retro-reflection: the detector at the source
    assert abs(back.arm_deg) < 1e-12


@example(s=-5e-324, to=1.0, phi=0.0, trans=False, p=0.0)  # a denormal that underflows
@settings(max_examples=200, deadline=None)
@given(s=st.floats(-89.0, 89.0), to=st.floats(-89.0, 89.0), phi=st.floats(-179.0, 179.0),
       trans=st.booleans(), p=angle)
def test_plan_angles_round_trip(s, to, phi, trans, p):
    stg = stage_angles(s, to, phi, trans, p)
    wi, wo = directions(stg.sample_deg, stg.arm_deg, stg.elevation_deg, stg.azimuth_deg)
    # undo the azimuth turn: the plan's frame has the plane of incidence as x-z
    c, sn = np.cos(np.radians(p)), np.sin(np.radians(p))
    turn = np.array([[c, -sn, 0], [sn, c, 0], [0, 0, 1]])
    wi0, wo0 = turn @ wi, turn @ wo
    forward = -1.0 if s < 0 else 1.0  # the side away from the source
    t, ph = np.radians(abs(to)), np.radians(phi + (180.0 if to < 0 else 0.0))
    expected = np.array([forward * np.sin(t) * np.cos(ph), np.sin(t) * np.sin(ph),
                         (-1 if trans else 1) * np.cos(t)])
    np.testing.assert_allclose(wo0, expected, atol=1e-9)
    np.testing.assert_allclose(wi0, [-np.sin(np.radians(s)), 0, np.cos(np.radians(s))],
                               atol=1e-12)
    ang = sample_angles(stg.sample_deg, stg.arm_deg, stg.elevation_deg, stg.azimuth_deg)
    assert abs(ang.theta_i_deg - abs(s)) < 1e-9
    assert (ang.theta_o_deg > 90.0) == trans or abs(ang.theta_o_deg - 90.0) < 1e-6


@settings(max_examples=200, deadline=None)
@given(s=angle, a=angle, e=st.floats(-89.0, 89.0), p=angle)
def test_agrees_with_sim_bench_geometry(s, a, e, p):
    wi, wo = directions(s, a, e, p)
    wi_b, wo_b = sample_frame_directions({"sample": s, "arm": a, "elevation": e, "azimuth": p})
    np.testing.assert_allclose(wi, wi_b, atol=1e-12)
    np.testing.assert_allclose(wo, wo_b, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(wo), 1.0, atol=1e-12)


def test_one_pose_is_the_vectorised_result_bit_for_bit():
    """The engine's one-pose path (numbers, math's sines) gives the vectorised angles exactly,
    signed zeros included (phi = +-180 hangs on them), so stored angles do not depend on it."""
    rng = np.random.default_rng(3)
    s, a, e, p = rng.uniform(-180, 180, (4, 200))
    e = e / 2.0
    edges = np.array([0.0, -0.0, 90.0, -90.0, 180.0, -180.0, 45.0])
    grid = np.stack(np.meshgrid(edges, edges, edges, edges), axis=-1).reshape(-1, 4)
    s, a, e, p = np.concatenate([np.stack([s, a, e, p], axis=1), grid]).T
    vec = sample_angles(s, a, e, p)
    for k in range(len(s)):
        one = sample_angles(float(s[k]), float(a[k]), float(e[k]), float(p[k]))
        assert all(type(x) is float for x in one)
        assert np.array(one).tobytes() == np.array([v[k] for v in vec]).tobytes(), k


def test_into_limits_picks_the_turn_inside_travel():
    np.testing.assert_allclose(into_limits([-30.0, 30.0, 180.0], (6.0, 354.0)),
                               [330.0, 30.0, 180.0])
    np.testing.assert_allclose(into_limits([200.0], (-180.0, 180.0)), [-160.0])
    assert np.isnan(into_limits([0.0], (6.0, 354.0)))[0]
