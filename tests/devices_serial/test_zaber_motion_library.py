"""Zaber's Motion Library (zaber-motion: a Go core in its wheel, Python bindings) drives the
Zaber emulator through its own serial port opening, sharing no code with gonio's driver or
with zaber.serial.

Identifying a device looks its id up in Zaber's device database, online or in a database file
from Zaber; neither can be had offline, so the devices are detected without identification
(the library then works in native units: microsteps, and maxspeed / accel data)."""

import pytest
from waiting import wait_until
from zaber_motion import Units
from zaber_motion.ascii import Connection
from zaber_motion.exceptions import CommandFailedException

from sim.devices.motion import VirtualClock
from sim.devices.zaber import ZaberEmulator


@pytest.fixture
def chain(opened):
    """Device 1 with one axis, device 2 with two (axis 2 without reference), at 50x real time,
    opened by zaber-motion."""
    emu = ZaberEmulator(VirtualClock(50.0), {
        (1, 1): {}, (2, 1): {}, (2, 2): {"limits_deg": (6.0, 354.0), "homed": False}})
    emu.start()
    opened.append(emu)
    with Connection.open_serial_port(emu.endpoint) as connection:
        yield emu, connection


@pytest.mark.thirdparty
def test_a_session_detects_reads_settings_homes_moves_and_hears_the_alerts(chain):
    emu, connection = chain
    alerts = []
    subscription = connection.alert.subscribe(alerts.append)
    try:
        devices = connection.detect_devices(identify_devices=False)
        assert [device.device_address for device in devices] == [1, 2]
        device = devices[0]
        assert device.settings.get("deviceid") == 50001
        assert device.settings.get("system.axiscount") == 1
        assert device.settings.get("version.build") == 12870
        assert device.settings.get("comm.alert") == 0  # Zaber devices ship with alerts off
        connection.enable_alerts()  # `set comm.alert 1` to every device, no reply awaited
        wait_until(lambda: all(d.settings["comm.alert"] for d in emu.devices.values()),
                   what="comm.alert 1 on every device")
        axis = device.get_axis(1)
        axis.home()  # waits until IDLE
        axis.move_absolute(64000, Units.NATIVE)  # 15 degrees
        assert axis.get_position(Units.NATIVE) == 64000
        assert emu.axis_position_deg((1, 1)) == pytest.approx(15.0)
        assert axis.settings.get("maxspeed") == 139810  # 20 deg/s
        received = wait_until(lambda: alerts if len(alerts) == 2 else None,
                              what="an alert at the end of the home and of the move")
        assert [(a.device_address, a.axis_number, a.status, a.warning_flag, a.data)
                for a in received] == [(1, 1, "IDLE", "--", "")] * 2
    finally:
        subscription.dispose()


@pytest.mark.thirdparty
def test_a_device_scope_get_answers_for_every_axis_and_rejections_name_the_reason(chain):
    emu, connection = chain
    device = connection.detect_devices(identify_devices=False)[1]
    arm = device.get_axis(2)
    arm.move_absolute(768000, Units.NATIVE)  # 180 degrees: it moves without a reference too
    assert device.all_axes.is_busy() is False
    assert device.settings.get_from_all_axes("pos") == [0, 768000]
    assert device.warnings.get_flags() == {"WR"}  # axis 2 was never homed
    with pytest.raises(CommandFailedException) as rejected:
        arm.move_absolute(99999999, Units.NATIVE)
    assert rejected.value.details.response_data == "BADDATA"
    replies = connection.generic_command_multi_response("get system.serial")
    assert sorted(reply.data for reply in replies) == ["120001", "120002"]
    assert device.generic_command("get peripheralid", axis=1, check_errors=False).data \
        == "BADCOMMAND"  # an integrated product has no peripheral
