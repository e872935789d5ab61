"""A third-party client drives the ESP emulator: InstrumentKit's NewportESP301 (its own serial
layer, pint quantities, and a TB? after every command), which shares no code with gonio's
driver or with PyMeasure's. A lab's session: identify, read positions, set units, speeds and
accelerations, move absolute and relative, wait, read errors."""

import math

import pytest
import serial

from sim.devices.esp import EspEmulator
from sim.devices.motion import VirtualClock

instruments = pytest.importorskip(
    "instruments", reason="InstrumentKit is not installed (pip install -e '.[clients]')")
from instruments.abstract_instruments.comm import SerialCommunicator  # noqa: E402
from instruments.newport import NewportESP301  # noqa: E402
from instruments.newport.errors import NewportError  # noqa: E402
from instruments.units import ureg  # noqa: E402

pytestmark = pytest.mark.thirdparty


@pytest.fixture
def controller():
    """An ESP301 with two rotation stages, moves instant, driven by InstrumentKit over a port
    the test opens (as open_serial() would, but closed here: InstrumentKit 1.0.0b2's own
    close() calls a socket's shutdown() on the serial port)."""
    axes = {1: {"limits_deg": (-95.0, 95.0), "stage_id": "URS100BCC, SN0042"}, 2: {}}
    with EspEmulator(VirtualClock(math.inf), axes) as emu, \
            serial.Serial(emu.endpoint, 19200, timeout=3, write_timeout=3) as port:
        yield emu, NewportESP301(SerialCommunicator(port))
    assert emu.server.handler_errors == []


def test_instrumentkit_session_identifies_configures_moves_and_reads_errors(controller):
    emu, ctl = controller
    assert ctl.query("VE?").strip() == "ESP301 Version 3.0.2 (emulated)"
    stage = ctl.axis[0]  # InstrumentKit counts axes from 0: this is axis 1 (it asks SN?)
    assert stage.axis_id == 1 and stage.units == ureg.deg
    assert stage.position == 0 * ureg.deg
    assert ctl.query("1ID?").strip() == "URS100BCC, SN0042"

    stage.enable()
    stage.max_velocity = 50 * ureg.deg / ureg.s
    stage.velocity = 25
    stage.max_acceleration = 500
    stage.acceleration = 100 * ureg.deg / ureg.s**2
    stage.deceleration = 100
    assert (stage.velocity, stage.max_velocity) == (25 * ureg.deg / ureg.s,
                                                   50 * ureg.deg / ureg.s)
    assert stage.acceleration == stage.deceleration == 100 * ureg.deg / ureg.s**2
    assert stage.max_acceleration == 500 * ureg.deg / ureg.s**2
    stage.jog_high_velocity = 20
    stage.jog_low_velocity = 2
    stage.homing_velocity = 10
    stage.jerk = 1000
    stage.error_threshold = 0.5
    assert (stage.jog_high_velocity, stage.jog_low_velocity, stage.homing_velocity) == (
        20 * ureg.deg / ureg.s, 2 * ureg.deg / ureg.s, 10 * ureg.deg / ureg.s)
    assert stage.error_threshold == 0.5 * ureg.deg
    assert stage.motor_type == NewportESP301.MotorType.dc_servo

    t0 = emu.clock.now()
    stage.move(30, absolute=True, wait=True)  # PA30, then WP30: the line holds until there
    assert stage.is_motion_done and stage.position == 30 * ureg.deg
    assert emu.clock.now() - t0 == pytest.approx(30 / 25 + 25 / 100)
    stage.move(-12.5 * ureg.deg, absolute=False)
    stage.wait_for_stop()
    status = stage.get_status()
    assert status["position"] == status["desired_position"] == 17.5 * ureg.deg
    assert status["desired_velocity"] == 0 * ureg.deg / ureg.s and status["is_motion_done"]
    assert emu.axis_position_deg(1) == 17.5

    with pytest.raises(NewportError) as err:
        stage.move(120, absolute=True)  # past the +95 software limit
    assert (err.value.axis, err.value.errcode) == (1, 6)
    with pytest.raises(NewportError) as err:
        stage.velocity = 80  # above VU
    assert (err.value.axis, err.value.errcode) == (1, 10)
    with pytest.raises(NewportError) as err:
        ctl.axis[1].move(5)  # motor 2 is off
    assert (err.value.axis, err.value.errcode) == (2, 13)
    assert stage.position == 17.5 * ureg.deg

    stage.units = NewportESP301.Units.radian
    assert stage.units == ureg.rad
    assert stage.position.magnitude == pytest.approx(math.radians(17.5), abs=1e-5)
    stage.units = ureg.deg
    stage.search_for_home()  # OR0: back to the home position
    stage.wait_for_stop()
    assert stage.position == 0 * ureg.deg
    stage.disable()
    assert emu.axes[1].motor_on is False
