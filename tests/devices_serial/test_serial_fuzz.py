"""Bad bytes into the ESP and PM100 emulators (random, truncated, over-long, wrong
terminator) give an error reply or silence, never a crash: hypothesis fuzzing, both on the
command interpreter and through the real pty."""

import math

import pytest
import serial
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from sim.devices.esp import EspEmulator
from sim.devices.motion import VirtualClock
from sim.devices.photodiode import ConstantPower
from sim.devices.pm100 import Pm100Emulator

ESP_WORDS = ["PA", "PR", "TP", "MD", "MO", "MF", "OR", "DH", "VA", "AC", "AG", "ST", "AB",
             "SL", "SR", "SN", "TE", "TB", "VE", "*IDN", "WS"]
SCPI_WORDS = ["*IDN", "*RST", "*CLS", "SYST", "SYSTEM", "ERR", "SENS", "SENSOR", "IDN",
              "MEAS", "MEASURE", "POW", "CONF", "INIT", "FETC", "READ", "CORR", "WAV",
              "RANG", "AUTO", "AVER", "COUN", "COLL", "ZERO", "MIN", "MAX"]
NUMBERS = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(-10**12, 10**12).map(str),
    st.sampled_from(["", "-", ".", "e5", "1e", "+-1", "1..2", "0x10", "1,2", "?"]),
)


def esp_units():
    unit = st.tuples(st.sampled_from(["", "0", "1", "2", "9", "12"]), st.sampled_from(ESP_WORDS),
                     st.sampled_from(["", "?"]), NUMBERS).map("".join)
    return st.lists(unit, max_size=6).map(";".join)


def scpi_units():
    header = st.lists(st.sampled_from(SCPI_WORDS), min_size=1, max_size=5).map(":".join)
    unit = st.tuples(st.sampled_from(["", ":"]), header, st.sampled_from(["", "?"]),
                     st.sampled_from(["", " "]), NUMBERS).map("".join)
    return st.lists(unit, max_size=5).map(";".join)


FAST = settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@FAST
@given(st.one_of(st.binary(max_size=400), esp_units().map(str.encode)))
@example(b"WS7.2e307;TB?")  # a wait past the horizon, then any error stamp
def test_esp_interpreter_never_raises(line):
    emu = EspEmulator(VirtualClock(math.inf), {1: {"motor_on": True}, 2: {}})
    reply = emu.handle_line(line)
    assert reply is None or (reply.endswith(b"\r\n") and reply.isascii())
    assert len(emu.errors) <= 10


@pytest.mark.parametrize("line", [
    b"WS7.2e307", b"1WS1.7e308", b"WS1e400", b"WSnan", b"WS-1",  # waits past the horizon
    b"1VA1e-300;1PA100", b"1AC1e-300;1PA100", b"1AG1e-300;1PA100",  # moves past it
    b"1SL-1e300;1PA-1e300", b"1SN9;1SL-1e307", b"1SN9;1DH1e307",  # infinite once in degrees
    b"1SL-1e300;1DH-1e300;1VA1e-10;1OR",  # a home search past it
])
def test_esp_refuses_what_its_clock_cannot_reach_and_keeps_serving(line):
    """A wait, move or setting whose value overflows is PARAMETER OUT OF RANGE (7, or x01 on an
    axis), buffered for TB?; the controller answers every line after it."""
    emu = EspEmulator(VirtualClock(math.inf), {1: {"motor_on": True}, 2: {}})
    assert emu.handle_line(line) is None
    code, _, text = emu.handle_line(b"TB?").decode().rstrip("\r\n").split(", ")
    assert (code, text) in {("7", "PARAMETER OUT OF RANGE"), ("101", "PARAMETER OUT OF RANGE")}
    assert emu.handle_line(b"TB?").startswith(b"0, ")
    position, code, _, text = emu.handle_line(b"2MO;2PA10;2WS;2TP?;TB?").split(b",")
    assert (position, code, text) == (b"10.00000", b"0", b" NO ERROR DETECTED\r\n")
    assert emu.handle_line(b"VE?") == b"ESP301 Version 3.0.2 (emulated)\r\n"


@FAST
@given(st.one_of(st.binary(max_size=400), scpi_units().map(str.encode)))
def test_pm100_interpreter_never_raises(line):
    emu = Pm100Emulator(ConstantPower(1e-6), seed=0)
    reply = emu.handle_line(line)
    assert reply is None or (reply.endswith(b"\n") and reply.isascii())
    assert len(emu.status.errors) <= 10


def stays_alive(emu, probe: bytes, eol: bytes, reply_eol: bytes, expect: bytes, garbage_strategy):
    """Write garbage (with any or no terminator), then check the probe is still answered."""
    with serial.Serial(emu.endpoint, 115200, timeout=2.0) as port:

        @settings(max_examples=25, deadline=None)
        @given(garbage_strategy, st.sampled_from([b"", b"\r", b"\n", b"\r\n", b"\n\r"]))
        def run(garbage, ending):
            port.write(garbage + ending + eol)  # the final eol ends any truncated line
            port.reset_input_buffer()
            port.write(probe + eol)
            for _ in range(50):  # skip answers the garbage itself asked for
                line = port.read_until(reply_eol)
                assert line, "emulator went silent"
                if line.lstrip().startswith(expect):
                    return
            pytest.fail("probe never answered")

        run()
    assert emu.server.handler_errors == []


def test_esp_pty_survives_garbage():
    with EspEmulator(VirtualClock(math.inf), {1: {}}) as emu:
        stays_alive(emu, b"VE?", b"\r", b"\r\n", b"ESP301",
                    st.one_of(st.binary(max_size=700), esp_units().map(str.encode)))


def test_pm100_pty_survives_garbage():
    with Pm100Emulator(ConstantPower(1e-6)) as emu:
        stays_alive(emu, b"*IDN?", b"\n", b"\n", b"Thorlabs,",
                    st.one_of(st.binary(max_size=700), scpi_units().map(str.encode)))


def test_drivers_raise_only_driver_errors_on_hostile_replies():
    """A device answering anything at all: the drivers return or raise a DriverError."""
    from drivers.base import DriverError
    from drivers.esp import EspController
    from drivers.pm100 import Pm100

    with EspEmulator(VirtualClock(math.inf), {1: {}}) as esp, \
            Pm100Emulator(ConstantPower(1e-6)) as pm, \
            EspController(esp.endpoint, timeout_s=0.05, retries=0) as ctl, \
            Pm100(pm.endpoint, timeout_s=0.05, retries=0) as meter:
        axis = ctl.axis(1)
        calls = [axis.position, axis.is_moving, axis.target, lambda: axis.move_to(1.0),
                 lambda: axis.limits_deg, axis.stop, meter.read, meter.sensor,
                 lambda: meter.range_w, lambda: meter.configure(633.0, 2, None)]
        reply = st.one_of(st.binary(max_size=60),
                          st.lists(st.sampled_from(["0", "1", "12.5", "-3e2", "nan", "x", "",
                                                    " NO ERROR DETECTED", '"No error"',
                                                    "106", "S121C"]),
                                   max_size=6).map(lambda p: ",".join(p).encode()),
                          st.lists(st.sampled_from(['0,"No error"', "1E-6", "1", "x", ""]),
                                   max_size=4).map(lambda p: ";".join(p).encode()))

        @settings(max_examples=60, deadline=None)
        @given(reply, st.sampled_from([b"\r\n", b"\n", b""]), st.sampled_from(range(len(calls))))
        def run(body, eol, which):
            esp.server.handler = pm.server.handler = lambda line: body + eol
            try:
                calls[which]()
            except DriverError:
                pass

        run()
