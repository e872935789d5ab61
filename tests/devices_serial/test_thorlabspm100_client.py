"""The `ThorlabsPM100` package (PyPI; a wrapper its author generated from the PM100 manual's SCPI
list, sharing no code with gonio) drives the PM100 emulator through a PyVISA resource on the
emulator's pty (`ASRL/dev/pts/N::INSTR`, pyvisa-py): a lab's session of identifying the meter
and its head, setting wavelength, averaging, unit, beam, filter and line frequency, reading
power three ways, and reading the OPERation and QUEStionable status registers."""

import math

import pytest
import pyvisa
from ThorlabsPM100 import ThorlabsPM100

from sim.devices.photodiode import ConstantPower
from sim.devices.pm100 import Pm100Emulator

pytestmark = pytest.mark.thirdparty
QUIET = {"read_noise_fraction": 0.0, "bandwidth_hz": 0.0, "dark_current_a": 0.0,
         "adc_bits": 32}
OPER_MEAS, OPER_SENS, OPER_DATA, QUES_POW = 16, 256, 512, 8


@pytest.fixture
def session():
    """(emulator, ThorlabsPM100 on a pyvisa ASRL resource): a PM100D with a germanium head."""
    with Pm100Emulator(ConstantPower(3e-4), sensor="S122C", model="PM100D", seed=2,
                       detector=QUIET) as emu:
        manager = pyvisa.ResourceManager("@py")
        inst = manager.open_resource(f"ASRL{emu.endpoint}::INSTR", baud_rate=115200,
                                     write_termination="\n", read_termination="\n",
                                     timeout=3000)
        try:
            yield emu, ThorlabsPM100(inst=inst), inst
        finally:
            inst.close()
            manager.close()
    assert emu.server.handler_errors == []


def test_a_lab_session_through_thorlabspm100(session):
    emu, meter, inst = session
    assert inst.query("*IDN?").startswith("Thorlabs,PM100D,")
    assert meter.system.sensor.idn.split(",")[0] == "S122C"
    assert meter.system.version == 1999.0
    assert meter.calibration.string.startswith('"')

    assert (meter.sense.correction.minimum_wavelength,
            meter.sense.correction.maximum_wavelength) == (700.0, 1800.0)
    meter.sense.correction.wavelength = 1310
    assert meter.sense.correction.wavelength == 1310.0 and emu.wavelength_nm == 1310.0
    meter.sense.average.count = 10
    assert meter.sense.average.count == 10 and emu.averaging == 10
    meter.sense.correction.beamdiameter = 3
    assert meter.sense.correction.beamdiameter == 3.0
    meter.input.pdiode.filter.lpass.state = 1
    assert meter.input.pdiode.filter.lpass.state == 1
    meter.system.lfrequency = 60
    assert meter.system.lfrequency == 60
    meter.display.brightness = 0.5
    assert meter.display.brightness == 0.5
    assert meter.sense.correction.power.pdiode.response > 0

    meter.configure.scalar.power()
    assert meter.getconfigure == "POW"
    assert meter.read == pytest.approx(3e-4, rel=1e-6)
    meter.initiate.immediate()
    assert meter.fetch == pytest.approx(3e-4, rel=1e-6)
    meter.sense.power.dc.unit = "DBM"
    assert meter.sense.power.dc.unit == "DBM"
    assert meter.read == pytest.approx(10 * math.log10(0.3), abs=1e-5)
    meter.sense.power.dc.unit = "W"
    assert meter.system.error.next == '0,"No error"'

    assert meter.status.operation.condition == OPER_SENS | OPER_DATA
    assert meter.status.operation.event & (OPER_MEAS | OPER_DATA) == OPER_MEAS | OPER_DATA
    assert meter.status.operation.event == 0  # read and cleared
    meter.status.operation.enable = OPER_DATA
    assert meter.status.operation.enable == OPER_DATA
    meter.abort()
    assert meter.status.operation.condition == OPER_SENS
    assert meter.status.questionable.condition == 0
    meter.status.questionable.ptransition = QUES_POW
    assert meter.status.questionable.ptransition == QUES_POW
    meter.sense.power.dc.range.upper = 1e-6  # far below the light: over range
    meter.sense.average.count = 1
    meter.read  # noqa: B018 (the property takes a reading)
    assert meter.status.questionable.condition == QUES_POW
    assert meter.status.questionable.event == QUES_POW
    assert meter.system.error.next == '0,"No error"'
