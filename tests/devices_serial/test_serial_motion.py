"""Virtual clock and trapezoidal axis: profiles checked analytically, scaled and instant time."""

import math
import time

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from waiting import wait_until

from sim.devices.motion import LimitError, MotionError, TrapezoidAxis, VirtualClock


def manual_axis(**kw):
    clock = VirtualClock(0.0)  # frozen: only advance() moves it
    defaults = dict(speed=10.0, accel=40.0, limits=(-100.0, 100.0))
    defaults.update(kw)
    return clock, TrapezoidAxis(clock, **defaults)


def analytic_position(t, d, v, a):
    """Rest-to-rest trapezoid/triangle position at time t for a move of d >= 0 from 0."""
    if d * a >= v * v:
        ta, tc = v / a, (d - v * v / a) / v
    else:
        ta, tc, v = math.sqrt(d / a), 0.0, math.sqrt(d * a)
    if t <= ta:
        return 0.5 * a * t * t
    if t <= ta + tc:
        return 0.5 * a * ta * ta + v * (t - ta)
    if t <= 2 * ta + tc:
        td = t - ta - tc
        return 0.5 * a * ta * ta + v * tc + v * td - 0.5 * a * td * td
    return d


def test_trapezoid_profile_matches_analytic_formula():
    clock, axis = manual_axis()
    end = axis.move_to(50.0)
    # v = 10, a = 40: t_acc = 0.25 s, accel distance 1.25, cruise 47.5 over 4.75 s
    assert end == pytest.approx(0.25 + 4.75 + 0.25)
    assert axis.duration(50.0) == pytest.approx(5.25)
    for t in [0.0, 0.1, 0.25, 1.0, 4.9, 5.0, 5.1, 5.25]:
        clock.advance_to(t)
        assert axis.position() == pytest.approx(analytic_position(t, 50.0, 10.0, 40.0), abs=1e-12)
    assert not axis.is_moving()
    assert axis.position() == 50.0


def test_triangle_profile_for_short_move_and_negative_direction():
    clock, axis = manual_axis(position=10.0)
    end = axis.move_by(-1.0)  # 1 < v^2/a = 2.5: triangle, t_acc = sqrt(1/40)
    ta = math.sqrt(1.0 / 40.0)
    assert end == pytest.approx(2 * ta)
    clock.advance_to(ta)
    assert axis.position() == pytest.approx(10.0 - 0.5)  # half way at the peak
    assert axis.velocity() == pytest.approx(-40.0 * ta)
    clock.advance_to(2 * ta)
    assert axis.position() == 9.0


@settings(max_examples=200, deadline=None)
@given(
    d=st.floats(1e-9, 1e4),
    v=st.floats(1e-3, 1e3),
    a=st.floats(1e-3, 1e4),
    frac=st.floats(0.0, 1.0),
)
def test_profile_property_matches_analytic_and_respects_speed(d, v, a, frac):
    clock, axis = manual_axis(speed=v, accel=a, limits=(-1e5, 1e5))
    end = axis.move_to(d)
    t = frac * end
    clock.advance_to(t)
    expected = analytic_position(t, d, v, a)
    assert axis.position() == pytest.approx(expected, rel=1e-9, abs=1e-9 * max(d, 1.0))
    assert abs(axis.velocity()) <= v * (1 + 1e-12)
    assert 0.0 <= axis.position() <= d * (1 + 1e-12)


def test_stop_decelerates_with_v2_over_2a_distance():
    clock, axis = manual_axis()
    axis.move_to(90.0)
    clock.advance_to(2.0)  # cruising at 10 deg/s
    p_before = axis.position()
    axis.stop()
    assert axis.is_moving()
    assert axis.target() == pytest.approx(p_before + 10.0**2 / (2 * 40.0))
    clock.advance(10.0 / 40.0)
    assert not axis.is_moving()
    assert axis.position() == pytest.approx(p_before + 1.25)


def test_abort_stops_immediately_and_cancels_homing():
    clock, axis = manual_axis(position=30.0)
    axis.home()
    clock.advance(1.0)
    p = axis.position()
    axis.abort()
    assert not axis.is_moving()
    clock.advance(100.0)
    assert axis.position() == p
    assert not axis.homed


def test_home_sets_homed_on_arrival():
    clock, axis = manual_axis(position=-20.0)
    end = axis.home()
    assert not axis.homed
    clock.advance_to(end)
    assert axis.homed and axis.position() == 0.0


def test_retarget_while_moving_decelerates_then_moves():
    clock, axis = manual_axis()
    axis.move_to(50.0)
    clock.advance_to(1.0)
    axis.move_to(0.0)
    clock.advance(100.0)
    assert axis.position() == 0.0
    assert not axis.is_moving()


def test_limits_and_bad_parameters_raise_clear_errors():
    _, axis = manual_axis()
    with pytest.raises(LimitError, match="positive software limit") as err:
        axis.move_to(100.5)
    assert err.value.side == "positive"
    with pytest.raises(LimitError, match="negative"):
        axis.move_by(-200.0)
    with pytest.raises(MotionError, match="speed"):
        axis.speed = 0.0
    with pytest.raises(MotionError, match="accel"):
        axis.accel = math.nan
    with pytest.raises(MotionError, match="finite"):
        axis.move_to(math.inf)
    with pytest.raises(ValueError, match="time_scale"):
        VirtualClock(-1.0)


def test_infinite_time_scale_completes_at_once_but_counts_duration():
    clock = VirtualClock(math.inf)
    axis = TrapezoidAxis(clock, speed=10.0, accel=40.0, limits=(-100, 100))
    t0 = clock.now()
    axis.move_to(50.0)
    assert not axis.is_moving()
    assert axis.position() == 50.0
    assert clock.now() - t0 == pytest.approx(5.25)
    # a second axis moving "at the same time" does not add its duration twice
    other = TrapezoidAxis(clock, speed=10.0, accel=40.0, position=0.0)
    other.move_to(-1.0)
    assert clock.now() - t0 == pytest.approx(5.25 + other.duration(1.0))


def test_axes_started_together_on_an_instant_clock_end_at_the_later_end():
    """As on a running clock, moves started at one instant overlap, however often the axes
    are looked at in between: the clock advances by the longest, not the sum; an axis's next
    move starts once its last one is over."""
    clock = VirtualClock(math.inf)
    first, second = (TrapezoidAxis(clock, speed=10.0, accel=40.0) for _ in range(2))
    assert first.move_to(50.0) == pytest.approx(5.25)
    assert not first.is_moving() and first.position() == 50.0
    assert second.move_to(20.0) == pytest.approx(2.25)
    assert not second.is_moving() and second.position() == 20.0
    assert clock.now() == pytest.approx(5.25)
    assert second.move_to(0.0) == pytest.approx(5.25 + 2.25)


def test_accelerated_time_scale_runs_in_real_time():
    clock = VirtualClock(1000.0)
    axis = TrapezoidAxis(clock, speed=100.0, accel=1000.0)
    end = axis.move_to(100.0)  # 1.1 virtual s = 1.1 ms real
    assert clock.real_seconds(end - clock.now()) < 0.01
    wait_until(lambda: not axis.is_moving(), what="the move's end")
    assert not axis.is_moving() and axis.position() == 100.0
    # bracket each clock reading between two real-time readings: exact, whatever the load
    r0, v0, r0b = time.monotonic(), clock.now(), time.monotonic()
    wait_until(lambda: clock.now() - v0 >= 50.0, what="50 virtual s (50 ms real)")
    r1, v1, r1b = time.monotonic(), clock.now(), time.monotonic()
    assert 1000.0 * (r1 - r0b) * (1 - 1e-9) <= v1 - v0 <= 1000.0 * (r1b - r0) * (1 + 1e-9)


def test_asymmetric_deceleration_profile():
    clock, axis = manual_axis(speed=10.0, accel=40.0, decel=10.0)
    # ramps: 100/80 + 100/20 = 6.25 deg; cruise (50 - 6.25)/10 = 4.375 s
    end = axis.move_to(50.0)
    assert end == pytest.approx(0.25 + 4.375 + 1.0)
    clock.advance_to(0.25 + 4.375 + 0.5)  # half-way through the 1 s deceleration
    assert axis.position() == pytest.approx(50.0 - 0.5 * 10.0 * 0.5**2)
    # a short move with a != b: peak sqrt(2 d a b / (a + b)) and d = vp^2/2a + vp^2/2b
    clock2, short = manual_axis(speed=100.0, accel=40.0, decel=10.0)
    vp = math.sqrt(2 * 2.0 * 40.0 * 10.0 / 50.0)
    assert short.move_to(2.0) == pytest.approx(vp / 40.0 + vp / 10.0)
    clock2.advance_to(vp / 40.0)
    assert short.velocity() == pytest.approx(vp)
    assert short.position() == pytest.approx(vp**2 / 80.0)


def test_home_position_defaults_to_nearest_limit_when_zero_is_outside():
    clock, arm = manual_axis(limits=(6.0, 354.0), position=180.0)
    clock.advance_to(arm.home())
    assert arm.position() == 6.0 and arm.homed
    clock, other = manual_axis(position=5.0, home_position=-3.0)
    clock.advance_to(other.home())
    assert other.position() == -3.0
    other.limits = (0.0, 10.0)
    with pytest.raises(LimitError):
        other.home()


def test_define_position_rebases_and_marks_homed():
    clock, axis = manual_axis(position=12.0)
    axis.define_position(0.0)
    assert axis.position() == 0.0 and axis.homed
    axis.move_to(5.0)
    with pytest.raises(MotionError, match="while moving"):
        axis.define_position(1.0)


def test_instant_moves_end_exactly_however_the_clock_sums_round():
    # 0.1 + (t_end - 0.1) need not round back to t_end: a move ended on an instant clock must
    # not still be reported moving, one unit in the last place short of its end
    clock = VirtualClock(math.inf)
    clock.advance(0.1)
    axis = TrapezoidAxis(clock, 20.0, 80.0, (-170.0, 170.0))
    axis.move_to(-2.732)
    assert not axis.is_moving() and axis.position() == -2.732
