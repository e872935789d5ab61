"""ModbusStage driver against the emulated stepper drive over real TCP and a real pty (RTU),
in both word orders: every register, every command, every refusal and error path."""

import math
import socket
import time

import pytest
from ticking_clock import TickingClock

from drivers.base import Axis, DeviceError, DeviceTimeout, DriverError
from drivers.modbus_stage import ModbusStage
from drivers.modbus_transport import ModbusTimeouts
from drivers.register_map import RegisterMapError


def test_registers_read_their_power_on_values(rig, link):
    r = rig(*link)
    assert isinstance(r.stage, Axis)
    assert r.stage.position() == 0.0
    assert r.stage.motion() == (20.0, 80.0)
    assert r.stage.limits() == (-95.0, 95.0)
    assert r.stage.status() == {"moving": False, "homed": False, "limit": False, "fault": False}
    assert r.stage.fault() == (0, "no fault")
    assert r.stage.read_value("target_position") == 0.0
    assert r.stage.read_value("command") == 0.0
    assert r.second.limits() == (-170.0, 170.0)  # a second unit on the same endpoint


def test_settings_round_trip_through_the_drive(rig, link):
    r = rig(*link)
    r.stage.set_motion(12.345, 67.891)
    r.stage.set_limits(-45.5, 88.125)
    assert r.stage.motion() == (12.345, 67.891)
    assert r.stage.limits() == (-45.5, 88.125)
    r.stage.write_value("target_position", -33.333)
    assert r.stage.read_value("target_position") == -33.333
    # the emulator decoded the same numbers from the words, in this word order
    assert r.stage_emu.registers.get("velocity") == pytest.approx(12.345)
    assert r.stage_emu.registers.get("limit_negative") == pytest.approx(-45.5)


def test_move_with_trapezoid_on_a_running_clock(rig, link):
    r = rig(*link, clock=TickingClock(0.01))  # each read of the clock: 10 virtual ms
    r.stage.move_to(30.0)  # 30 deg at 20 deg/s, 80 deg/s^2: 1.75 virtual s
    assert r.stage.is_moving()
    assert 0.0 <= r.stage.position() < 30.0
    assert r.stage.wait(60.0) == 30.0
    assert not r.stage.is_moving()
    assert r.stage_emu.axis_position_deg() == 30.0
    assert r.second.position() == 0.0  # the other unit did not move


def test_move_home_and_negative_positions(rig, link):
    r = rig(*link)
    r.stage.move_to(-87.654)
    assert r.stage.wait(1.0) == -87.654
    assert not r.stage.homed()
    r.stage.home()
    assert r.stage.wait(1.0) == 0.0
    assert r.stage.homed()


def test_stop_decelerates_and_abort_halts_at_once(rig, link):
    r = rig(*link, clock=TickingClock(0.001))
    r.stage.move_to(90.0)  # 4.75 virtual s
    r.stage_emu.axis.clock.advance(0.1)
    r.stage.stop()
    stopped = r.stage.wait(60.0)
    assert 0.0 < stopped < 90.0
    r.stage.move_to(-90.0)
    r.stage_emu.axis.clock.advance(0.1)
    r.stage.abort()
    assert not r.stage.is_moving()
    assert r.stage.position() == pytest.approx(r.stage_emu.axis_position_deg(), abs=1e-3)


def test_target_past_limit_is_refused_with_the_maps_fault(rig, link):
    r = rig(*link)
    with pytest.raises(DeviceError, match="sample: device error 1: target outside") as err:
        r.stage.move_to(120.0)
    assert err.value.code == 1
    assert r.stage.status() == {"moving": False, "homed": False, "limit": True, "fault": True}
    assert r.stage.position() == 0.0
    r.stage.clear_fault()
    assert r.stage.fault() == (0, "no fault")
    r.stage.move_to(10.0)  # a good move also clears a fault
    assert r.stage.wait(1.0) == 10.0


@pytest.mark.parametrize("register, value, code", [
    ("velocity", 1000.0, 2), ("acceleration", 20000.0, 3), ("velocity", 0.0, 2)])
def test_out_of_range_setting_written_raw_refuses_the_next_move(rig, register, value, code):
    r = rig("tcp")
    reg = r.stage.map.register(register)
    raw = round(value * reg.scale)  # bypass the driver's own range check: a foreign host
    r.stage.link.write("raw", reg.address, [raw >> 16, raw & 0xFFFF], 1)
    with pytest.raises(DeviceError, match=f"device error {code}") as err:
        r.stage.move_to(5.0)
    assert err.value.code == code and r.stage.position() == 0.0
    assert r.stage.status()["fault"] and not r.stage.status()["limit"]


def test_inverted_limits_refuse_home(rig):
    r = rig("rtu")
    r.stage.set_limits(10.0, -10.0)
    with pytest.raises(DeviceError, match="device error 4: software limits invalid"):
        r.stage.home()


def test_home_goes_to_the_nearest_limit_when_zero_is_outside_them(rig):
    r = rig("tcp")
    r.stage.set_limits(-30.0, -6.0)
    r.stage.home()
    assert r.stage.wait(1.0) == -6.0
    assert r.stage.homed()


@pytest.mark.parametrize("transport", ["tcp", "rtu"])
def test_modbus_exceptions_become_device_errors(rig, transport):
    r = rig(transport)
    st = r.stage.map.register("status")
    with pytest.raises(DeviceError, match="Modbus exception 02: illegal data address"):
        r.stage.link.write("sample", st.address, [1], 1)  # read-only register
    with pytest.raises(DeviceError, match="Modbus exception 03: illegal data value"):
        r.stage.write_value("command", 99)  # not a command of the map
    with pytest.raises(DeviceError, match="Modbus exception 02"):
        r.stage.link.read("sample", "holding", 14, 2, 1)  # past the map's last register
    with pytest.raises(DeviceError, match="Modbus exception 02"):
        r.stage.link.read("sample", "input", 0, 1, 1)  # the drive has no input registers


def test_driver_checks_values_before_any_write(rig):
    r = rig("tcp")
    with pytest.raises(RegisterMapError, match="velocity = 800.0 outside"):
        r.stage.set_motion(800.0, 10.0)
    with pytest.raises(RegisterMapError, match="does not fit a int32"):
        r.stage.move_to(3e6)
    with pytest.raises(ValueError, match="finite"):
        r.stage.move_to(math.nan)
    with pytest.raises(ValueError, match="not writable"):
        r.stage.write_value("status", 1)
    assert r.stage.motion() == (20.0, 80.0)


def test_wait_times_out_by_name(rig):
    r = rig("tcp", time_scale=0.0)  # a frozen clock: the move never ends
    r.stage.move_to(90.0)
    with pytest.raises(DeviceTimeout, match="sample: timeout after 0.05 s waiting for end of"):
        r.stage.wait(0.05)
    r.stage.abort()


def test_absent_unit_on_rtu_bus_times_out_and_tcp_gateway_answers_11(rig, tmp_path):
    r = rig("rtu", reply_s=0.05, read_retries=1)
    with ModbusStage("rtu", r.server.endpoint, 9, r.stage_map, name="ghost", read_retries=1,
                     timeouts=ModbusTimeouts(reply_s=0.05)) as ghost:  # the bus's own line
        t0 = time.monotonic()
        with pytest.raises(DeviceTimeout, match="ghost: timeout after 0.05 s waiting for"):
            ghost.position()
        assert time.monotonic() - t0 < 1.0  # bounded: two attempts of 0.05 s and pauses
    assert r.stage.position() == 0.0  # the bus still works
    t = rig("tcp", reply_s=0.2)
    host, port = t.server.endpoint.split(":")
    with ModbusStage("tcp", host, 9, t.stage_map, tcp_port=int(port), name="ghost",
                     timeouts=ModbusTimeouts(reply_s=0.2)) as ghost:  # the server's link's
        with pytest.raises(DeviceError, match="Modbus exception 11"):
            ghost.position()


def test_connection_refused_is_a_named_driver_error(rig):
    r = rig("tcp")
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]  # closed again: nothing listens there
    with ModbusStage("tcp", "127.0.0.1", 1, r.stage_map, tcp_port=port, name="nowhere",
                     timeouts=ModbusTimeouts(reply_s=0.2)) as stage:
        with pytest.raises(DriverError, match=f"nowhere: connection to 127.0.0.1:{port}"):
            stage.position()


def test_bad_unit_id_and_missing_map_entries_fail_before_traffic(rig, tmp_path):
    r = rig("tcp", reply_s=0.2)
    host, port = r.server.endpoint.split(":")
    link = dict(tcp_port=int(port), timeouts=ModbusTimeouts(reply_s=0.2))  # the rig's link's
    with pytest.raises(ValueError, match="unit id must be an integer in 0..247"):
        ModbusStage("tcp", host, 300, r.stage_map, **link)
    broken = tmp_path / "no-home.toml"
    broken.write_text(r.stage_map.read_text().replace("home = 3", ""))
    with pytest.raises(RegisterMapError, match=r"\[commands\] lacks home"):
        ModbusStage("tcp", host, 1, broken, **link)
