"""Zaber ASCII driver against its emulator over a real pty: motion, limits, settings read
back, home and faults, a daisy chain, and injected reply faults (never a wrong position)."""

import math

import pytest
from ticking_clock import TickingClock
from waiting import wait_until

from drivers.base import Axis, DeviceError, DeviceTimeout, DriverError, ProtocolError
from drivers.serial_transport import SerialPortError
from drivers.zaber import ZaberController
from sim.devices.faults import FaultInjector, FaultSpec
from sim.devices.motion import VirtualClock, profile_times
from sim.devices.zaber import ZaberEmulator

UNIT = 0.015 / 64  # X-RSW60A microstep at the default resolution, degrees
AXES = {
    1: {"limits_deg": (-95.0, 95.0), "speed_deg_s": 20.0, "accel_deg_s2": 80.0},
    2: {"limits_deg": (-170.0, 170.0), "homed": False},
}


@pytest.fixture
def zaber_pair(start_pair):
    """make(time_scale, axes, timeout_s, retries, clock) -> (emulator, controller)."""

    def make(time_scale=math.inf, axes=None, timeout_s=0.3, retries=2, clock=None):
        emu = ZaberEmulator(clock or VirtualClock(time_scale), axes or AXES)
        return start_pair(emu, ZaberController, timeout_s=timeout_s, retries=retries,
                          name="zaber")

    return make


def inject(emu, **spec):
    emu.server.faults = FaultInjector(FaultSpec(**spec))


def confirmed(call) -> bool:
    """Run call(): True if it returned, False if a lost reply left its command unconfirmed
    (which the driver must say it did not re-send)."""
    try:
        call()
    except DriverError as exc:
        assert "not re-sent" in str(exc) or isinstance(exc, DeviceTimeout)
        return False
    return True


def test_open_sets_checksums_and_reads_identity(zaber_pair):
    emu, ctl = zaber_pair()
    assert emu.devices[1].settings["comm.checksum"] == 1
    assert emu.devices[1].settings["comm.alert"] == 0
    axis = ctl.axis(1, "sample")
    assert isinstance(axis, Axis) and axis.name == "sample"
    assert axis.identity() == ctl.identity() == {
        "device_id": "50001", "serial": "120001", "firmware": "7.38", "address": "1"}
    assert axis.microstep_deg == UNIT
    with pytest.raises(ValueError, match="device 1 has axes 1..2, got 3"):
        ctl.axis(3)


def test_move_wait_position_on_a_running_clock(zaber_pair):
    emu, ctl = zaber_pair(clock=TickingClock(0.01))  # each read of the clock: 10 virtual ms
    axis = ctl.axis(1)
    duration = sum(profile_times(40.0, 20.0, 80.0))  # 2.25 virtual s
    t0 = emu.clock.now()
    axis.move_to(40.0)
    assert axis.is_moving()
    assert 0.0 < axis.position() < 40.0
    assert axis.wait(timeout_s=60.0) == pytest.approx(40.0, abs=UNIT)
    # the wait lasted the move and returned at the first poll that saw it done
    assert duration <= emu.clock.now() - t0 < duration + 0.1
    assert not axis.is_moving()
    assert emu.axis_position_deg(1) == axis.position() == round(40.0 / UNIT) * UNIT


def test_targets_beyond_the_limits_are_rejected_naming_the_axis(zaber_pair):
    emu, ctl = zaber_pair()
    axis = ctl.axis(1, "sample")
    axis.move_to(10.0)
    with pytest.raises(DeviceError, match=r"^sample: device error BADDATA: .*'move abs 426667'"):
        axis.move_to(100.0)
    assert axis.position() == pytest.approx(10.0, abs=UNIT)
    assert emu.received["move abs"] == 2


def test_configure_sends_each_setting_once_and_reads_it_back(zaber_pair):
    emu, ctl = zaber_pair()
    axis = ctl.axis(1)
    axis.configure(30.0, 120.0, (100.0, 160.0))  # above the old limits: limit.max goes first
    assert axis.speed_deg_s == pytest.approx(30.0, rel=1e-6)
    assert axis.accel_deg_s2 == pytest.approx(120.0, rel=0.01)  # 1.43 deg/s^2 per unit
    assert axis.limits_deg == pytest.approx((100.0, 160.0), abs=UNIT)
    for setting in ("maxspeed", "accel", "limit.min", "limit.max"):
        assert emu.received[f"set {setting}"] == 1
    motion = emu.axes[1].motion
    assert motion.speed == pytest.approx(axis.speed_deg_s)
    assert motion.limits == pytest.approx(axis.limits_deg)
    with pytest.raises(DeviceError, match=r"device error BADDATA.*'set maxspeed"):
        axis.configure(500.0, 120.0, (100.0, 160.0))  # above the stage's maximum speed
    with pytest.raises(ValueError, match="lo < hi"):
        axis.configure(30.0, 120.0, (10.0, -10.0))
    assert emu.received["set maxspeed"] == 2


def test_stop_decelerates_and_estop_stops_at_once(zaber_pair):
    emu, ctl = zaber_pair(clock=TickingClock(0.001))
    axis = ctl.axis(1, "sample")
    axis.move_to(90.0)  # 4.75 virtual s
    emu.clock.advance(0.5)  # past the 0.25 s ramp, cruising at 20 deg/s
    axis.stop()
    p_stop = emu.axes[1].motion.target()
    assert p_stop < 90.0
    assert axis.wait(60.0) == pytest.approx(p_stop, abs=UNIT)
    assert axis.warning == "NI"  # the stop interrupted the move; it does not block the next
    axis.move_to(-90.0)
    emu.clock.advance(0.5)
    axis.estop()
    assert not axis.is_moving()
    p = axis.position()
    emu.clock.advance(0.25)
    assert axis.position() == p
    ctl.estop()  # the whole device
    assert emu.received["estop"] == 2


def test_an_unreferenced_axis_moves_only_after_homing(zaber_pair):
    emu, ctl = zaber_pair()
    axis = ctl.axis(2, "arm")
    assert axis.warning == "WR"
    with pytest.raises(DeviceError, match=r"arm: device error WR: no reference position"):
        axis.move_to(5.0)
    assert emu.received["move abs"] == 0
    axis.home()
    assert axis.wait(1.0) == 0.0
    axis.move_to(-150.0)
    assert axis.wait(1.0) == pytest.approx(-150.0, abs=UNIT)


def test_a_home_cut_short_is_no_arrival(zaber_pair):
    emu, ctl = zaber_pair(clock=TickingClock(0.001))
    axis = ctl.axis(1)
    emu.axes[1].motion.define_position(30.0)  # homing back takes 1.75 virtual s
    axis.home()
    axis.stop()
    with pytest.raises(DeviceError, match="no reference position"):
        axis.wait(60.0)


def test_a_latched_fault_stops_the_scan_until_home(zaber_pair):
    emu, ctl = zaber_pair(clock=TickingClock(0.01))
    axis = ctl.axis(1, "sample")
    axis.move_to(60.0)
    emu.clock.advance(0.25)  # under way
    emu.raise_fault(1, "FS")
    with pytest.raises(DeviceError, match=r"sample: device error FS: stalled and stopped"):
        axis.wait(60.0)
    with pytest.raises(DeviceError, match="FS"):
        axis.move_to(0.0)
    axis.home()  # acknowledges the fault (warnings clear), then homes
    assert emu.received["warnings clear"] == 1
    assert axis.wait(60.0) == 0.0
    axis.move_to(20.0)
    assert axis.wait(60.0) == pytest.approx(20.0, abs=UNIT)


def test_a_fault_raised_between_polls_stops_the_move_it_blocks(zaber_pair):
    emu, ctl = zaber_pair(clock=TickingClock(0.01))
    axis = ctl.axis(1)
    emu.raise_fault(1, "FQ")  # the driver has not seen it yet
    with pytest.raises(DeviceError, match="FQ: encoder error"):
        axis.move_to(80.0)
    assert emu.received["stop"] == 1 and emu.received["move abs"] == 1


def test_a_daisy_chain_of_devices(zaber_pair):
    emu, ctl = zaber_pair(axes={(1, 1): {}, (2, 1): {}, (2, 2): {"limits_deg": (6, 354)}},
                          timeout_s=0.1)
    sample, arm, elevation = ctl.axis(1), ctl.axis(1, "arm", address=2), ctl.axis(2, address=2)
    assert elevation.name == "zaber.2.2"
    assert sample.identity()["serial"] == "120001" and arm.identity()["serial"] == "120002"
    sample.move_to(-30.0)
    arm.move_to(45.0)
    elevation.move_to(300.0)
    assert [emu.axis_position_deg(k) for k in ((1, 1), (2, 1), (2, 2))] == pytest.approx(
        [-30.0, 45.0, 300.0], abs=UNIT)
    assert emu.devices[2].settings["comm.checksum"] == 1
    with pytest.raises(DriverError, match=r"not confirmed .*timeout"):
        ctl.axis(1, address=7)  # nobody on the chain answers to 7


def test_every_dropped_byte_is_caught_never_a_wrong_position(zaber_pair):
    emu, ctl = zaber_pair(retries=0)
    axis = ctl.axis(1)
    axis.move_to(12.5)
    inject(emu, drop_prob=1.0, seed=5)
    for _ in range(30):
        with pytest.raises(ProtocolError, match="zaber: "):
            axis.position()
    assert emu.server.faults.counts["drop"] == 30
    inject(emu, drop_prob=0.5, seed=6)
    ctl.transport.retries = 12
    assert {axis.position() for _ in range(20)} == {round(12.5 / UNIT) * UNIT}


def test_corrupted_replies_are_detected_and_queries_retried(zaber_pair):
    emu, ctl = zaber_pair(retries=0)
    axis = ctl.axis(1)
    inject(emu, corrupt_prob=1.0)
    with pytest.raises(ProtocolError, match="zaber: garbled reply"):
        axis.position()
    inject(emu, corrupt_prob=0.5, seed=2)
    ctl.transport.retries = 10
    assert [axis.position() for _ in range(10)] == [0.0] * 10
    assert emu.server.faults.counts["corrupt"] > 0


def test_stalled_replies_time_out_after_bounded_retries_then_resync(zaber_pair):
    emu, ctl = zaber_pair(timeout_s=0.1, retries=2)
    axis = ctl.axis(1)
    inject(emu, stall_prob=1.0)
    with pytest.raises(DeviceTimeout, match=r"zaber: timeout after 0.1 s waiting for get pos"):
        axis.position()
    stalls = emu.server.faults.counts
    # the emulator may read the last attempt after the driver gave it up (a loaded machine)
    wait_until(lambda: stalls["stall"] >= 1 + 2, what="three stalled attempts")
    assert stalls["stall"] == 1 + 2  # 1 + 2 attempts
    inject(emu)
    assert axis.position() == 0.0
    assert ctl.transport.resyncs == 1


def test_late_replies_are_never_taken_for_later_ones(zaber_pair):
    emu, ctl = zaber_pair(timeout_s=0.1, retries=0)
    axis = ctl.axis(1)
    axis.move_to(10.0)
    inject(emu, latency_s=0.15)  # every reply misses its timeout
    with pytest.raises(DeviceTimeout):
        axis.position()
    inject(emu)
    emu.axes[1].motion.move_to(20.0)  # the stage moves on; the late reply says 10
    assert axis.position() == pytest.approx(20.0, abs=UNIT)
    assert ctl.transport.resyncs == 1


def test_a_motion_command_is_never_resent_when_its_reply_is_lost(zaber_pair):
    emu, ctl = zaber_pair(timeout_s=0.1, retries=4)
    axis = ctl.axis(1)
    inject(emu, stall_prob=0.3, seed=11)
    moved = sum(confirmed(lambda i=i: axis.move_to(float(i))) for i in range(12))
    assert emu.received["move abs"] == 12  # each move_to sent exactly one move abs
    assert emu.server.faults.counts["stall"] > 0
    assert moved >= 9  # lost replies were settled by reading the position back


def test_settings_are_sent_once_and_hold_whenever_configure_returns(zaber_pair):
    emu, ctl = zaber_pair(timeout_s=0.05, retries=6)
    axis = ctl.axis(1)
    inject(emu, stall_prob=0.2, seed=3)
    returned = 0
    for speed in range(10, 15):
        if confirmed(lambda speed=speed: axis.configure(speed, 80.0, (-95.0, 95.0))):
            returned += 1
            assert emu.axes[1].maxspeed == round(speed / UNIT * 1.6384)
    assert emu.received["set maxspeed"] == 5  # once per configure, never re-sent
    assert returned >= 4 and emu.server.faults.counts["stall"] > 0


def test_disconnect_is_a_named_driver_error(zaber_pair):
    emu, ctl = zaber_pair()
    axis = ctl.axis(1)
    inject(emu, disconnect_after=1)
    axis.position()
    with pytest.raises(SerialPortError, match=r"zaber: serial port /dev/\S+ went away"):
        for _ in range(3):
            axis.position()


def test_open_failure_names_port():
    with pytest.raises(DriverError, match="serial port /dev/nonexistent-zaber could not be"):
        ZaberController("/dev/nonexistent-zaber", name="stages")
