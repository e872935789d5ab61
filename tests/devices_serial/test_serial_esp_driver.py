"""ESP300/301 driver against its emulator over a real pty: commands, errors, timeouts, faults."""

import math
import time

import pytest
from ticking_clock import TickingClock

from drivers.base import Axis, DeviceError, DeviceTimeout, DriverError, ProtocolError
from drivers.esp import EspController
from sim.devices.faults import FaultInjector, FaultSpec
from sim.devices.motion import profile_times


def inject(emu, **spec):
    emu.server.faults = FaultInjector(FaultSpec(**spec))


def raw(ctl, line):
    """One exchange of raw text through the driver's transport (reply line)."""
    return ctl.transport.exchange(line)


def test_identity_and_axis_interface(esp_pair):
    emu, ctl = esp_pair()
    assert ctl.version.startswith("ESP301 Version")
    assert raw(ctl, "*IDN?").startswith("Newport Corporation,ESP301")
    axis = ctl.axis(1, "sample")
    assert isinstance(axis, Axis) and axis.name == "sample"
    assert axis.identity() == ctl.identity() == {"version": emu.version}
    assert axis.enabled
    assert ctl.query("1SN?") == "7"  # degrees


def test_move_wait_position_on_a_running_clock(esp_pair):
    emu, ctl = esp_pair(clock=TickingClock(0.01))  # each read of the clock: 10 virtual ms
    axis = ctl.axis(1)
    duration = sum(profile_times(40.0, 20.0, 80.0))  # 2.25 virtual s
    t0 = emu.clock.now()
    axis.move_to(40.0)
    assert axis.is_moving()
    assert 0.0 < axis.position() < 40.0
    assert axis.wait(timeout_s=60.0) == pytest.approx(40.0)
    # the wait lasted the move and returned at the first poll that saw it done (a poll reads
    # the clock three times)
    assert duration <= emu.clock.now() - t0 < duration + 0.1
    assert not axis.is_moving()
    assert emu.axis_position_deg(1) == pytest.approx(40.0)


def test_instant_time_scale_counts_virtual_duration(esp_pair):
    emu, ctl = esp_pair()
    axis = ctl.axis(2)
    t0 = emu.clock.now()
    axis.move_to(-90.0)
    assert not axis.is_moving() and axis.position() == -90.0
    assert emu.clock.now() - t0 == pytest.approx(sum(profile_times(90.0, 30.0, 120.0)))


def test_relative_move_and_define_position(esp_pair):
    emu, ctl = esp_pair()
    axis = ctl.axis(1)
    axis.move_to(10.0)
    axis.move_by(-2.5)
    assert axis.target() == pytest.approx(7.5) and axis.wait(1.0) == pytest.approx(7.5)
    axis.define_position(0.0)
    assert axis.position() == 0.0
    assert emu.axes[1].motion.homed


def test_number_forms_and_several_commands_on_one_line(esp_pair):
    emu, ctl = esp_pair()
    ctl.axis(1)
    for form in ["30", "30.0", "3e1", "+3.0E+01", "30.", " 30"]:
        assert raw(ctl, f"1PA0;1PA{form};1PA?;2TP?;TE?") == "30.00000,0.00000,0"
    assert raw(ctl, "1pa 12.5 ; 1tp?") == "12.50000"  # case and spaces


def test_stop_decelerates_and_abort_stops_at_once(esp_pair):
    emu, ctl = esp_pair(clock=TickingClock(0.001))
    axis = ctl.axis(1, "sample")
    axis.move_to(90.0)  # 4.75 virtual s
    emu.clock.advance(0.5)  # past the 0.25 s ramp, cruising at 20 deg/s
    axis.stop()
    p_stop = emu.axes[1].motion.target()
    assert p_stop < 90.0
    final = axis.wait(60.0)
    assert final == pytest.approx(p_stop)
    axis.move_to(-90.0)
    emu.clock.advance(0.5)
    ctl.abort()
    assert not axis.is_moving()
    p = axis.position()
    emu.clock.advance(0.25)
    assert axis.position() == p
    assert emu.received["AB"] == 1


def test_home_and_homing_errors(esp_pair):
    emu, ctl = esp_pair(clock=TickingClock(0.01))
    axis = ctl.axis(1)
    emu.axes[1].motion.define_position(30.0)  # homing back takes 1.75 virtual s
    axis.home()
    assert axis.is_moving()
    with pytest.raises(DeviceError) as err:
        axis.move_to(5.0)
    assert err.value.code == 130 and "HOMING" in err.value.text
    axis.stop()  # reports 120 HOMING ABORTED, which stop() expects
    assert not emu.axes[1].motion.homed and ctl.errors() == []
    assert raw(ctl, "1OR;1ST;TE?") == "120"
    axis.home()
    assert axis.wait(60.0) == 0.0
    assert emu.axes[1].motion.homed


def test_software_limits(esp_pair):
    emu, ctl = esp_pair()
    a1, a2 = ctl.axis(1), ctl.axis(2)
    with pytest.raises(DeviceError, match="106: POSITIVE SOFTWARE LIMIT") as err:
        a1.move_to(95.5)
    assert err.value.device == "esp"
    with pytest.raises(DeviceError, match="207: NEGATIVE SOFTWARE LIMIT"):
        a2.move_to(-171.0)
    assert a1.position() == 0.0 and a2.position() == 0.0
    a1.limits_deg = (-10.0, 20.0)
    assert a1.limits_deg == (-10.0, 20.0)
    with pytest.raises(DeviceError, match="106"):
        a1.move_by(25.0)
    a1.limits_deg = (30.0, 40.0)  # moving both bounds up keeps SL < SR in between
    assert a1.limits_deg == (30.0, 40.0)
    with pytest.raises(DeviceError, match="101: PARAMETER OUT OF RANGE"):
        ctl.command("1SL50")


def test_speed_acceleration_settings_and_their_errors(esp_pair):
    emu, ctl = esp_pair()
    axis = ctl.axis(1)
    axis.speed_deg_s, axis.accel_deg_s2, axis.decel_deg_s2 = 45.0, 300.0, 150.0
    assert (axis.speed_deg_s, axis.accel_deg_s2, axis.decel_deg_s2) == (45.0, 300.0, 150.0)
    assert emu.axes[1].motion.decel == 150.0
    with pytest.raises(DeviceError, match="110: MAXIMUM VELOCITY EXCEEDED"):
        axis.speed_deg_s = 500.0
    with pytest.raises(DeviceError, match="111: MAXIMUM ACCELERATION EXCEEDED"):
        axis.accel_deg_s2 = 1e5
    with pytest.raises(DeviceError, match="101"):
        axis.decel_deg_s2 = -1.0
    assert axis.speed_deg_s == 45.0


def test_motor_off_refuses_motion(esp_pair):
    emu, ctl = esp_pair()
    axis = ctl.axis(1)
    axis.disable()
    assert not axis.enabled
    with pytest.raises(DeviceError, match="113: MOTOR NOT ENABLED"):
        axis.move_to(1.0)
    with pytest.raises(DeviceError, match="113"):
        axis.home()
    axis.enable()
    axis.move_to(1.0)


@pytest.mark.parametrize(
    "line, code",
    [
        ("1XY5", 6),  # command does not exist
        ("1PAabc", 7),  # not a number
        ("1PA1e999", 7),  # not finite
        ("4TP?", 9),  # no such axis
        ("PA5", 37),  # axis number missing
        ("1VA", 38),  # parameter missing
        ("1SN2", 101),  # a rotary stage cannot be in mm
        ("1OR9", 101),  # home search modes are 0..6
        ("TE5", 7),  # a query takes no parameter
    ],
)
def test_general_and_axis_error_codes(esp_pair, line, code):
    emu, ctl = esp_pair()
    with pytest.raises(DeviceError) as err:
        ctl.command(line)
    assert err.value.code == code
    assert str(code) in str(err.value) and "esp" in str(err.value)


def test_query_error_raises_without_waiting_for_a_timeout(esp_pair):
    emu, ctl = esp_pair(timeout_s=2.0)
    with pytest.raises(DeviceError, match="9: AXIS NUMBER OUT OF RANGE"):
        ctl.query("7TP?")
    assert emu.received["TP?"] == 1  # asked once: no timeout, so no retry


def test_error_buffer_fifo_te_tb_and_depth(esp_pair):
    emu, ctl = esp_pair()
    raw(ctl, "1YY;PA1;TE?")  # YY: no such command; an answer keeps the exchange synchronous
    assert ctl.errors() == [(37, "AXIS NUMBER MISSING")]  # TE? already took the 6
    for _ in range(12):
        ctl.transport.send("1YY")
    assert raw(ctl, "TE?") == "6"
    assert len(ctl.errors()) == 9  # 10 kept, one read by TE?
    code, stamp, text = raw(ctl, "TB?").split(", ")
    assert (code, text) == ("0", "NO ERROR DETECTED") and stamp.isdigit()


def test_units_change_scales_positions(esp_pair):
    emu, ctl = esp_pair()
    axis = ctl.axis(1)
    axis.move_to(45.0)
    raw(ctl, "1SN9;TE?")
    assert float(ctl.query("1TP?")) == pytest.approx(math.pi / 4, abs=1e-5)
    ctl.command("1PA0.5")  # radians now
    assert emu.axis_position_deg(1) == pytest.approx(math.degrees(0.5))
    axis.enable()  # back to degrees (SN7)
    assert axis.position() == pytest.approx(math.degrees(0.5), abs=1e-5)


def test_wait_for_stop_holds_the_command_line(esp_pair):
    emu, ctl = esp_pair(clock=TickingClock(0.05), timeout_s=60.0)  # WS polls every 2 ms
    ctl.axis(1)
    t0 = emu.clock.now()
    assert raw(ctl, "1PA20;1WS100;1TP?") == "20.00000"  # 1.25 s + 0.1 s virtual
    # held until the stop, then 100 ms; every clock read ticks 50 ms, so a few reads past it
    assert 1.35 <= emu.clock.now() - t0 < 1.35 + 0.5
    assert raw(ctl, "WS;1MD?") == "1"


def test_wait_timeout_is_named(esp_pair):
    emu, ctl = esp_pair(time_scale=0.0)  # a frozen clock: the move never ends
    axis = ctl.axis(2, "arm")
    axis.move_to(150.0)
    with pytest.raises(DeviceTimeout, match=r"arm: timeout after 0.05 s waiting for motion done"):
        axis.wait(0.05)
    axis.stop()


def test_stalled_replies_time_out_after_bounded_retries(esp_pair):
    emu, ctl = esp_pair(timeout_s=0.1, retries=2)
    axis = ctl.axis(1)
    inject(emu, stall_prob=1.0)
    with pytest.raises(DeviceTimeout, match=r"esp: timeout after 0.1 s waiting for 1TP\?"):
        axis.position()
    assert emu.server.faults.counts["stall"] == 1 + 2  # 1 + 2 retries, bounded


def test_motion_command_is_never_resent_when_its_status_is_lost(esp_pair):
    emu, ctl = esp_pair(timeout_s=0.1, retries=4)
    axis = ctl.axis(1)
    inject(emu, stall_prob=0.3, seed=11)
    confirmed = 0
    for i in range(12):
        try:
            axis.move_to(float(i))
            confirmed += 1
        except (DeviceTimeout, DriverError):
            pass
    assert emu.received["PA"] == 12  # each move_to sent exactly one PA
    assert emu.received["PA?"] >= 1  # lost statuses were settled by re-reading the target
    assert confirmed >= 9
    assert emu.server.faults.counts["stall"] > 0


def test_corrupted_replies_are_detected_and_queries_retried(esp_pair):
    emu, ctl = esp_pair(retries=1)
    axis = ctl.axis(1)
    axis.move_to(12.5)
    inject(emu, corrupt_prob=1.0)
    with pytest.raises(ProtocolError, match="esp: garbled reply"):
        axis.position()
    inject(emu, corrupt_prob=0.5, seed=2)
    ctl.transport.retries = 6
    assert [axis.position() for _ in range(10)] == [12.5] * 10
    assert emu.server.faults.counts["corrupt"] > 0


def test_dropped_bytes_never_hang_and_are_caught_when_structure_breaks(esp_pair):
    emu, ctl = esp_pair(retries=0)
    axis = ctl.axis(1)
    axis.move_to(12.5)
    inject(emu, drop_prob=1.0, seed=5)
    outcomes = []
    for _ in range(40):
        try:
            outcomes.append(axis.position())
        except ProtocolError as exc:
            assert str(exc).startswith("esp:")
            outcomes.append("garbled")
        except DeviceError as exc:  # a dropped byte turned "0," into another code
            outcomes.append(exc.code)
    assert "garbled" in outcomes
    # the rest parsed: a lost integer digit (12.5 -> 2.5) or timestamp digit keeps every shape
    assert emu.server.faults.counts["drop"] == 40


def test_latency_is_added_but_within_timeout(esp_pair):
    emu, ctl = esp_pair(timeout_s=0.5)
    axis = ctl.axis(1)
    inject(emu, latency_s=0.05)
    t0 = time.monotonic()
    axis.position()
    assert time.monotonic() - t0 >= 0.05


def test_bad_crc_has_no_meaning_on_ascii_serial(esp_pair):
    emu, ctl = esp_pair()
    axis = ctl.axis(1)
    inject(emu, bad_crc_prob=1.0)
    assert axis.position() == 0.0


def test_disconnect_is_a_named_driver_error(esp_pair):
    emu, ctl = esp_pair()
    axis = ctl.axis(1)
    inject(emu, disconnect_after=2)
    axis.position()
    axis.position()
    # the hangup can land while the query is written or while its reply is read
    lost = r"esp: serial port /dev/\S+ went away \((reading the reply to |writing ')1TP\?"
    with pytest.raises(DriverError, match=lost):
        for _ in range(3):
            axis.position()


def test_open_failure_names_port():
    with pytest.raises(DriverError, match="serial port /dev/nonexistent-esp could not be opened"):
        EspController("/dev/nonexistent-esp", name="stages")


def test_tb_timestamp_counts_400us_servo_ticks(esp_pair):
    emu, ctl = esp_pair()
    ctl.axis(1).move_to(40.0)  # instant clock: advances by the move's 2.25 s
    code, stamp, text = raw(ctl, "1PA500;TB?").split(", ")
    assert (code, text) == ("106", "POSITIVE SOFTWARE LIMIT DETECTED")
    assert int(stamp) == int(sum(profile_times(40.0, 20.0, 80.0)) / 400e-6)
