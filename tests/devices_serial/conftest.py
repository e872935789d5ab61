"""Fixtures: emulators on real ptys and drivers connected to them (stopped after each test)."""

import math

import pytest
import serial
from waiting import HANG_S

from drivers.esp import EspController
from drivers.pm100 import Pm100
from sim.devices.esp import EspEmulator
from sim.devices.faults import FaultSpec
from sim.devices.motion import VirtualClock
from sim.devices.photodiode import ConstantPower
from sim.devices.pm100 import Pm100Emulator
from sim.devices.pty_server import PtyDevice

AXES = {
    1: {"limits_deg": (-95.0, 95.0), "speed_deg_s": 20.0, "accel_deg_s2": 80.0},
    2: {"limits_deg": (-170.0, 170.0), "speed_deg_s": 30.0, "accel_deg_s2": 120.0},
}


@pytest.fixture
def make_esp():
    """make_esp(time_scale=inf, faults=None, axes=AXES, seed=0, clock=None) -> started
    EspEmulator (on `clock` if given, else a VirtualClock at time_scale)."""
    started = []

    def make(time_scale=math.inf, faults=None, axes=None, seed=0, clock=None):
        emu = EspEmulator(clock or VirtualClock(time_scale), axes or AXES,
                          faults=FaultSpec(**faults) if faults else None, seed=seed)
        emu.start()
        started.append(emu)
        return emu

    yield make
    for emu in started:
        emu.stop()
        assert emu.server.handler_errors == []


@pytest.fixture
def esp_pair(make_esp):
    """make(time_scale, faults, timeout_s, retries, axes, clock) -> (emulator, controller)."""
    controllers = []

    def make(time_scale=math.inf, faults=None, timeout_s=0.3, retries=2, axes=None,
             clock=None):
        emu = make_esp(time_scale, faults, axes, clock=clock)
        ctl = EspController(emu.endpoint, timeout_s=timeout_s, retries=retries, name="esp")
        controllers.append(ctl)
        return emu, ctl

    yield make
    for ctl in controllers:
        ctl.close()


@pytest.fixture
def opened():
    """Where a test's pair fixture puts the emulators it starts and the drivers it opens: after
    the test, last opened first, drivers are closed and emulators stopped (and must have met
    no handler error)."""
    things = []
    yield things
    for thing in reversed(things):
        if isinstance(thing, PtyDevice):
            thing.stop()
            assert thing.server.handler_errors == []
        else:
            thing.close()


@pytest.fixture
def start_pair(opened):
    """start(emulator, driver_class, **options) -> (emulator, driver): the emulator started
    and the driver opened on its endpoint with `options`, both closed after the test."""

    def start(emulator, driver_class, **options):
        emulator.start()
        opened.append(emulator)
        driver = driver_class(emulator.endpoint, **options)
        opened.append(driver)
        return emulator, driver

    return start


@pytest.fixture
def plain_port(opened):
    """serve(emulator, baudrate) -> a plain pyserial session with the emulator, started on a
    pty (reads wait HANG_S at most: a hang guard), both closed after the test."""

    def serve(emulator, baudrate):
        emulator.start()
        opened.append(emulator)
        port = serial.Serial(emulator.endpoint, baudrate, timeout=HANG_S)
        opened.append(port)
        return port

    return serve


@pytest.fixture
def pm_pair(start_pair):
    """make(power_w, faults, timeout_s, retries, detector) -> (emulator, driver)."""

    def make(power_w=2e-6, faults=None, timeout_s=0.3, retries=2, detector=None, source=None):
        emu = Pm100Emulator(source or ConstantPower(power_w),
                            faults=FaultSpec(**faults) if faults else None,
                            seed=3, detector=detector)
        return start_pair(emu, Pm100, timeout_s=timeout_s, retries=retries, name="pm100")

    return make


class ScpiPort:
    """A plain pyserial session with a SCPI emulator: the bytes a client writes (LF-ended) and
    the lines it reads back (reads wait HANG_S at most: a hang guard, never a verdict)."""

    def __init__(self, endpoint: str):
        self.port = serial.Serial(endpoint, 115200, timeout=HANG_S)

    def send(self, text: str) -> None:
        """Write one program message."""
        self.port.write(text.encode("ascii") + b"\n")

    def ask(self, text: str) -> str:
        """Write a program message and read its one response line (without the LF)."""
        self.send(text)
        line = self.port.readline()
        assert line.endswith(b"\n"), f"no answer to {text!r} (got {line!r})"
        return line.decode("ascii")[:-1]

    def errors(self) -> list[int]:
        """Drain the error queue: the codes in order."""
        codes = []
        while (code := int(self.ask("SYST:ERR?").split(",")[0])) != 0:
            codes.append(code)
        return codes

    def close(self) -> None:
        self.port.close()


@pytest.fixture
def scpi(opened):
    """start(power_w=2e-6, **Pm100Emulator options) -> (emulator, ScpiPort): a PM100 emulator
    on a pty and a raw session with it, both closed after the test."""

    def start(power_w=2e-6, **options):
        emu = Pm100Emulator(ConstantPower(power_w), **options)
        emu.start()
        opened.append(emu)
        port = ScpiPort(emu.endpoint)
        opened.append(port)
        return emu, port

    return start
