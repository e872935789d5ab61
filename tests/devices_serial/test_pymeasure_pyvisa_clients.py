"""Third-party clients drive the emulators over their ptys: PyMeasure's own drivers
(newport.ESP300, thorlabs.ThorlabsPM100USB) and plain PyVISA (pyvisa-py, ASRL resources),
none of which shares code with gonio's drivers. Each moves or reads and queries errors."""

import pytest
import pyvisa
from pymeasure.instruments.newport import ESP300
from pymeasure.instruments.newport.esp300 import AxisError, GeneralError
from pymeasure.instruments.thorlabs import ThorlabsPM100USB

from sim.devices.esp import EspEmulator
from sim.devices.motion import VirtualClock
from sim.devices.photodiode import ConstantPower
from sim.devices.pm100 import Pm100Emulator

pytestmark = [
    pytest.mark.thirdparty,
    # PyMeasure warns that it does not know whether these two speak SCPI.
    pytest.mark.filterwarnings("ignore:It is not known whether this device:FutureWarning"),
]
VISA = {"visa_library": "@py", "timeout": 3000}


@pytest.fixture
def esp():
    """An ESP301 with PyMeasure's three default axes (x, y, phi), at 5x real time."""
    with EspEmulator(VirtualClock(5.0), {1: {}, 2: {}, 3: {}}) as emu:
        yield emu
    assert emu.server.handler_errors == []


@pytest.fixture
def pm100():
    with Pm100Emulator(ConstantPower(2e-6), seed=4, model="PM100USB") as emu:
        yield emu
    assert emu.server.handler_errors == []


@pytest.fixture
def visa():
    manager = pyvisa.ResourceManager("@py")
    yield manager
    manager.close()


def test_pymeasure_esp300_moves_homes_and_reads_the_error_fifo(esp):
    controller = ESP300(f"ASRL{esp.endpoint}::INSTR", **VISA)
    try:
        assert controller.id == "Newport Corporation,ESP301,0,3.0.2"
        stage = controller.x
        stage.enable()
        assert stage.enabled and stage.units == "degree"
        assert (stage.left_limit, stage.right_limit) == (-170.0, 170.0)
        stage.position = 12.0  # 12 deg at 20 deg/s: 0.6 s virtual, 0.12 s real
        assert not stage.motion_done
        stage.wait_for_stop()
        assert stage.motion_done and stage.position == 12.0
        assert esp.axis_position_deg(1) == 12.0
        stage.right_limit = 20.0
        stage.position = 25.0  # past the new right limit: refused, the stage stays
        controller.y.position = 5.0  # motor off
        controller.write("*OPC?")  # not in the ESP command set
        errors = controller.errors
        assert [type(e) for e in errors] == [AxisError, AxisError, GeneralError]
        assert [(getattr(e, "axis", None), e.message) for e in errors] == [
            ("1", "POSITIVE SOFTWARE LIMIT DETECTED"), ("2", "MOTOR NOT ENABLED"),
            (None, "COMMAND DOES NOT EXIST"),
        ]
        assert controller.error == 0 and stage.position == 12.0
        stage.home(0)
        stage.wait_for_stop()
        assert stage.position == 0.0
        stage.define_position(7.5)
        assert stage.position == 7.5 and esp.axis_position_deg(1) == 7.5
        stage.disable()
        assert not stage.enabled
    finally:
        controller.adapter.close()


def test_pymeasure_pm100usb_reads_power_sets_wavelength_and_reads_errors(pm100):
    meter = ThorlabsPM100USB(f"ASRL{pm100.endpoint}::INSTR", **VISA)
    try:
        assert meter.id.startswith("Thorlabs,PM100USB,")
        assert (meter.sensor_name, meter.sensor_sn) == ("S121C", "EMU00001")
        assert meter.is_power_sensor and meter.wavelength_settable
        assert not meter.is_energy_sensor
        assert meter.power == pytest.approx(2e-6, rel=0.05)
        assert (meter.wavelength_min, meter.wavelength_max) == (400.0, 1100.0)
        meter.wavelength = 850
        assert meter.wavelength == 850.0 and pm100.wavelength_nm == 850.0
        meter.wavelength = 5000  # PyMeasure truncates to the sensor's range
        assert meter.wavelength == 1100.0
        meter.write("SENS:CORR:WAV 5")  # below the range: SCPI -222
        meter.write("SENS:POW:FOO 1")  # no such header: -113
        assert meter.check_errors() == [[-222.0, '"Data out of range"'],
                                        [-113.0, '"Undefined header"']]
        assert meter.next_error == [0.0, '"No error"']
        with pytest.raises(AttributeError, match="not an energy sensor"):
            _ = meter.energy
    finally:
        meter.adapter.close()


def test_pyvisa_asrl_moves_the_esp_and_reads_its_errors(esp, visa):
    port = visa.open_resource(f"ASRL{esp.endpoint}::INSTR", baud_rate=19200,
                              write_termination="\r", read_termination="\r\n", timeout=3000)
    try:
        assert port.query("VE?") == "ESP301 Version 3.0.2 (emulated)"
        assert port.query("2MO;2VA30;2PA-40;2WS;2TP?") == "-40.00000"
        assert port.query_ascii_values("1TP;2TP;2MD?") == [0.0, -40.0, 1.0]
        port.write("2PA-400")
        code, stamp, text = port.query("TB?").split(", ")
        assert (code, text) == ("207", "NEGATIVE SOFTWARE LIMIT DETECTED") and stamp.isdigit()
        assert port.query("TE?") == "0"
    finally:
        port.close()


def test_pyvisa_asrl_reads_the_pm100_and_its_error_queue(pm100, visa):
    port = visa.open_resource(f"ASRL{pm100.endpoint}::INSTR", baud_rate=115200,
                              write_termination="\n", read_termination="\n", timeout=3000)
    try:
        assert port.query("*IDN?").startswith("Thorlabs,PM100USB,")
        port.write("SENS:POW:RANG:AUTO OFF;:SENS:POW:RANG 1E-5")
        assert port.query_ascii_values("POW:RANG?;:SENS:AVER:COUN 8;COUN?",
                                     separator=";") == [1e-5, 8.0]
        (power,) = port.query_ascii_values("MEAS:POW?")
        assert power == pytest.approx(2e-6, rel=0.05)
        port.write("SENS:AVER:COUN 0")
        assert port.query("SYST:ERR?") == '-222,"Data out of range"'
        assert port.query("SYST:ERR?") == '0,"No error"'
    finally:
        port.close()
