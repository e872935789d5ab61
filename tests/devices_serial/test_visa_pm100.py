"""The PM100 driver, unchanged, through PyVISA (pyvisa-py) against the real emulator, over both
links a test can reach: a pty as an ASRL resource (what sim serves for a PM100USB's USB-TMC
resource) and raw TCP on 127.0.0.1 as a TCPIP SOCKET resource. Reading, settings, a late
reply brought back in step, the link lost; and plain PyVISA as a client of the same."""

import re
import threading

import pytest
import pyvisa
from waiting import HANG_S

from drivers.base import DeviceError, DeviceTimeout, Reading
from drivers.pm100 import Pm100
from drivers.serial_transport import SerialPortError
from sim.devices.faults import FaultInjector, FaultSpec
from sim.devices.photodiode import ConstantPower
from sim.devices.pm100 import Pm100Emulator
from sim.devices.pty_server import LOOPBACK
from sim.served_resources import serve_resource

pytestmark = pytest.mark.thirdparty
QUIET = {"read_noise_fraction": 1e-3, "dark_current_a": 0.0, "bandwidth_hz": 0.0}
#: what a config names, and the shape of the resource the emulator serves for it
LINKS = {
    "usb-as-asrl": ("USB0::0x1313::0x8072::P2000001::INSTR", r"ASRL/dev/pts/\d+::INSTR"),
    "tcpip-socket": ("TCPIP0::192.0.2.7::5025::SOCKET", r"TCPIP0::127\.0\.0\.1::\d+::SOCKET"),
}


class Power:
    """A light source whose power the test sets."""

    def __init__(self, power_w: float):
        self.power_w_now = power_w

    def __call__(self) -> float:
        return self.power_w_now


class HeldReading(FaultInjector):
    """Holds the first reply that carries a reading (READ?;:SENS:POW:RANG?;:SYST:ERR?: three
    answers) until the test releases it: a reply that comes after the driver's timeout."""

    def __init__(self):
        super().__init__()
        self.holding, self.release = threading.Event(), threading.Event()

    def reply(self, data: bytes, keep_tail: int = 0, crc_bytes: int = 0) -> bytes | None:
        if data.count(b";") == 2 and not self.holding.is_set():
            self.holding.set()
            self.release.wait(HANG_S)
        return super().reply(data, keep_tail, crc_bytes)


@pytest.fixture(params=list(LINKS))
def link(request):
    """(the resource a config names, the pattern of the one the emulator serves for it)."""
    return LINKS[request.param]


@pytest.fixture
def served(opened, link):
    """serve(emulator) -> the VISA resource of the started emulator (stopped after the test)."""
    def serve(emulator: Pm100Emulator) -> str:
        opened.append(emulator)
        resource = serve_resource(emulator, link[0], LOOPBACK)
        assert re.fullmatch(link[1], resource), resource
        return resource

    return serve


@pytest.fixture
def visa_pm(opened, served):
    """make(source, timeout_s, retries, detector) -> (emulator, driver opened by its
    resource, the resource)."""
    def make(source=None, timeout_s=0.3, retries=2, detector=None):
        emu = Pm100Emulator(source or ConstantPower(2e-6), seed=3, detector=detector,
                            model="PM100USB")
        resource = served(emu)
        pm = Pm100(resource=resource, timeout_s=timeout_s, retries=retries, name="pm100")
        opened.append(pm)
        return emu, pm, resource

    return make


def test_identity_and_readings_through_visa(visa_pm):
    emu, pm, resource = visa_pm(source=ConstantPower(3.3e-6), detector=QUIET)
    assert pm.transport.port == resource and pm.transport.link.noun == "VISA resource"
    assert pm.idn == emu.idn and pm.idn.startswith("Thorlabs,PM100USB,")
    assert pm.identity()["sensor_name"] == emu.sensor.name
    reading = pm.read()
    assert isinstance(reading, Reading) and reading.range_w == 1e-5 and not reading.saturated
    assert reading.power_w == pytest.approx(3.3e-6, abs=5e-8)
    assert pm.measure() == pytest.approx(3.3e-6, abs=5e-8)


def test_settings_and_device_errors_through_visa(visa_pm):
    emu, pm, _ = visa_pm(detector={"ranges_w": [3e-8, 3e-7, 3e-6, 3e-5]})
    pm.configure(wavelength_nm=850.0, averaging=16, range_w=3e-6)
    assert (pm.wavelength_nm, pm.averaging, pm.range_w) == (850.0, 16, 3e-6)
    assert (emu.wavelength_nm, emu.averaging, emu.autorange) == (850.0, 16, False)
    assert pm.full_scales_w() == (3e-8, 3e-7, 3e-6, 3e-5) and pm.range_w == 3e-6
    pm.configure(632.8, 1, None)
    assert pm.range_w is None and emu.autorange
    assert pm.wavelength_limits_nm() == (400.0, 1100.0)
    with pytest.raises(DeviceError) as err:
        pm.query("SENS:CORR:WAV 300")  # below the sensor's range
    assert err.value.code == -222 and pm.errors() == []


def test_a_late_reading_is_never_taken_for_the_next_one(visa_pm):
    light = Power(2e-6)
    emu, pm, _ = visa_pm(source=light, timeout_s=0.2, retries=0, detector=QUIET)
    held = emu.server.faults = HeldReading()
    try:
        with pytest.raises(DeviceTimeout, match=r"^pm100: timeout after 0.2 s waiting for "
                                                r":READ\?;:SENS:POW:RANG\?$"):
            pm.read()
        assert held.holding.is_set() and not pm.transport.in_step
        light.power_w_now = 6e-6  # the held reply says 2 uW; the light is 6 uW now
    finally:
        held.release.set()
    assert pm.read().power_w == pytest.approx(6e-6, abs=5e-8)
    assert pm.transport.in_step and pm.transport.resyncs == 1


def test_a_stalled_reply_is_retried_a_bounded_number_of_times(visa_pm):
    emu, pm, _ = visa_pm(timeout_s=0.1, retries=1)
    emu.server.faults = FaultInjector(FaultSpec(stall_prob=1.0))
    with pytest.raises(DeviceTimeout, match="pm100: timeout after 0.1 s waiting for :READ"):
        pm.read()
    assert emu.server.faults.counts["stall"] == 1 + 1


def test_the_link_lost_is_one_error_naming_the_resource(visa_pm):
    emu, pm, resource = visa_pm(timeout_s=0.2)
    pm.read()
    emu.stop()
    for call in (pm.read, lambda: pm.wavelength_nm, pm.errors):
        with pytest.raises(SerialPortError, match=rf"^pm100: VISA resource "
                                                  rf"{re.escape(resource)} went away \(\w"):
            call()
    pm.close()
    pm.close()  # closing a vanished link is quiet and idempotent


@pytest.mark.parametrize("resource, why", [
    ("ASRL/dev/nonexistent-pm100::INSTR", r"could not be opened: .*No such file"),
    ("NOT-A-RESOURCE", r"could not be opened: Could not parse NOT-A-RESOURCE"),
    ("GPIB0::INTFC", r"could not be opened: INTFC resources exchange no lines"),
])
def test_a_resource_that_cannot_be_opened_is_one_error_naming_it(resource, why):
    with pytest.raises(SerialPortError, match=rf"^pm100: VISA resource {re.escape(resource)} "
                                              rf"{why}"):
        Pm100(resource=resource, name="pm100")


def test_pyvisa_queries_the_emulator_directly(served):
    emu = Pm100Emulator(ConstantPower(2e-6), seed=4, model="PM100USB")
    port = pyvisa.ResourceManager("@py").open_resource(
        served(emu), read_termination="\n", write_termination="\n", timeout=3000)
    try:
        assert port.query("*IDN?") == emu.idn
        assert float(port.query("MEAS:POW?")) == pytest.approx(2e-6, rel=0.05)
        port.write("SENS:CORR:WAV 5")  # below the sensor's range: SCPI -222
        assert port.query("SYST:ERR?") == '-222,"Data out of range"'
        assert port.query_ascii_values("SENS:AVER:COUN 8;COUN?", separator=";") == [8.0]
    finally:
        port.close()  # (the manager stays: closing it would close the process's every resource)
