"""The Thorlabs FW102C / FW212C filter wheel: its emulator against the manual's exchanges over a
real pty, move times on the virtual clock, the driver selecting wavelengths through its
filters, device errors, lost and garbled replies (a move sent once, queries asked again), and
pylablib's FW driver (a third-party client) driving the emulator."""

import math

import pytest
from reply_faults import GarbleNext, StallNext, read_through_faults, spy_lines

from drivers.base import (
    DeviceError,
    DeviceTimeout,
    DriverError,
    ProtocolError,
    WavelengthSelector,
)
from drivers.fw102c import Filter, Fw102cWheel
from sim.devices.faults import FaultInjector, FaultSpec
from sim.devices.fw102c import IDN, Fw102cConfigError, Fw102cEmulator
from sim.devices.motion import VirtualClock

FILTERS = [(1, 450.0, 10.0), (2, 532.0, 3.0), (4, 632.8, 1.0)]


class DropDigitOnce(FaultInjector):
    """Drops the first digit of the next reply that says position 12 (a shape-keeping drop)."""

    def __init__(self):
        super().__init__(FaultSpec())
        self.done = False

    def reply(self, data, keep_tail=0, crc_bytes=0):
        if not self.done and b"\r12\r" in data:
            self.done = True
            return data.replace(b"\r12\r", b"\r2\r")
        return super().reply(data, keep_tail, crc_bytes)


class DropDigitEvery(FaultInjector):
    """Drops the first digit of every other reply that says position 12, the first one too."""

    def __init__(self):
        super().__init__(FaultSpec())
        self.seen = 0

    def reply(self, data, keep_tail=0, crc_bytes=0):
        if b"\r12\r" in data:
            self.seen += 1
            if self.seen % 2 == 1:
                return data.replace(b"\r12\r", b"\r2\r")
        return super().reply(data, keep_tail, crc_bytes)


@pytest.fixture
def wheel(start_pair):
    """make(positions=6, speed="high", faults=None, **driver options) -> (emulator, driver),
    on an instant clock (`emulator.clock`)."""

    def make(positions=6, filters=FILTERS, faults=None, timeout_s=0.3, retries=2, **options):
        emu = Fw102cEmulator(VirtualClock(math.inf), positions=positions,
                             faults=FaultSpec(**faults) if faults else None, seed=4)
        return start_pair(emu, Fw102cWheel, filters=filters, positions=positions,
                          timeout_s=timeout_s, retries=retries, **options)

    return make


@pytest.fixture
def terminal(plain_port):
    """start(**emulator options) -> (emulator, ask): the wheel on a pty and ask(line) -> the
    bytes it sends back up to and with its prompt, as a terminal program sees them."""

    def start(**options):
        emu = Fw102cEmulator(VirtualClock(math.inf), **options)
        port = plain_port(emu, 115200)

        def ask(line):
            port.write(line.encode("ascii") + b"\r")
            return port.read_until(b"> ")

        return emu, ask

    return start


def test_every_line_is_echoed_answered_and_prompted_as_the_manual_gives(terminal):
    emu, ask = terminal()
    assert ask("*idn?") == f"*idn?\r{IDN}\r> ".encode()
    assert ask("pos?") == b"pos?\r1\r> "
    assert ask("pos=4") == b"pos=4\r> "
    assert ask("pos?") == b"pos?\r4\r> "
    assert ask("pcount?") == b"pcount?\r6\r> "
    for keyword, value in (("trig", "1"), ("speed", "0"), ("sensors", "1"), ("baud", "0")):
        assert ask(f"{keyword}={value}") == f"{keyword}={value}\r> ".encode()
        assert ask(f"{keyword}?") == f"{keyword}?\r{value}\r> ".encode()
    assert ask("save") == b"save\r> "
    assert emu.saved == {"pcount": 6, "trig": 1, "speed": 0, "sensors": 1, "baud": 0}
    assert ask("pcount=12") == b"pcount=12\r> " and ask("pcount?") == b"pcount?\r12\r> "


def test_unknown_keywords_and_bad_arguments_get_the_manuals_error_strings(terminal):
    emu, ask = terminal()
    not_defined, invalid = b"Command error CMD_NOT_DEFINED", b"Command error CMD_ARG_INVALID"
    # an empty line too: a client opening the wheel sends one and expects CMD_NOT_DEFINED
    for line in ("", "POS?", "position?", "pos", "*idn=1", "pos?3"):
        assert ask(line) == line.encode() + b"\r" + not_defined + b"\r> "
    for line in ("pos=0", "pos=7", "pos=x", "pos=", "pcount=8", "speed=2", "trig=-1"):
        assert ask(line) == line.encode() + b"\r" + invalid + b"\r> "
    assert emu.position == 1 and emu.moves == 0  # nothing refused moved the wheel


@pytest.mark.parametrize("speed, half_turn_s", [("high", 3.0), ("slow", 6.0)])
def test_moves_take_the_shorter_way_round_on_the_virtual_clock(wheel, speed, half_turn_s):
    emu, drv = wheel(speed=speed, filters=[(p, 400.0 + p, 5.0) for p in range(1, 7)])
    start = emu.clock.now()
    drv.move_to_position(4)  # 1 -> 4: half a turn of the 6-position wheel
    assert emu.clock.now() - start == pytest.approx(half_turn_s)
    drv.move_to_position(6)  # two positions on
    assert emu.clock.now() - start == pytest.approx(half_turn_s * (1 + 2 / 3))
    drv.move_to_position(1)  # 6 -> 1 is one position the short way round
    assert emu.clock.now() - start == pytest.approx(half_turn_s * 2)
    assert drv.position() == 1 and emu.moves == 3


def test_the_driver_selects_wavelengths_through_the_configured_filters(wheel):
    emu, drv = wheel()
    assert isinstance(drv, WavelengthSelector)
    assert drv.identity() == {"idn": IDN}
    assert drv.wavelengths_nm() == (450.0, 532.0, 632.8)
    assert drv.wavelength_nm() == 450.0 and drv.bandwidth_nm() == 10.0
    drv.move_to_nm(632.8)
    assert drv.wait(1.0) == 632.8 and emu.position == 4
    assert drv.current_filter() == Filter(4, 632.8, 1.0)
    with pytest.raises(ValueError, match=r"fw102c: no filter centred on 600 nm \(filters: "
                                         r"450, 532, 632.8 nm\)"):
        drv.move_to_nm(600.0)
    with pytest.raises(ValueError, match="no filter at position 3"):
        drv.move_to_position(3)
    emu.position = 3  # turned by hand to an empty slot
    with pytest.raises(DriverError, match="at position 3, where the config names no filter"):
        drv.wavelength_nm()
    assert emu.position == 3 and emu.moves == 1


def test_the_wheel_must_be_the_type_the_config_names(start_pair):
    emu = Fw102cEmulator(VirtualClock(math.inf), positions=12)
    with pytest.raises(DriverError, match=r"the wheel has 12 positions \(pcount\?\), the "
                                          "config says 6"):
        start_pair(emu, Fw102cWheel, filters=FILTERS, positions=6, timeout_s=0.3)


def test_a_filter_beyond_the_wheel_is_refused_when_it_opens(start_pair):
    emu = Fw102cEmulator(VirtualClock(math.inf))
    with pytest.raises(DriverError, match="a filter at position 9, beyond the wheel's 6"):
        start_pair(emu, Fw102cWheel, filters=[(9, 500.0, 10.0)], timeout_s=0.3)


def test_the_emulator_refuses_a_wheel_it_cannot_be():
    with pytest.raises(Fw102cConfigError, match="positions must be 6 or 12, got 8"):
        Fw102cEmulator(positions=8)
    with pytest.raises(Fw102cConfigError, match=r"position must be 1..6, got 7"):
        Fw102cEmulator(position=7)


def test_a_device_error_names_the_manuals_code(wheel):
    _, drv = wheel()
    with pytest.raises(DeviceError, match="fw102c: device error CMD_NOT_DEFINED: no such "
                                          "command or query"):
        drv.query("filter?")
    with pytest.raises(DeviceError, match="CMD_ARG_INVALID: argument wrong or out of range"):
        drv.command("speed=5", lambda: False)


def test_a_move_whose_reply_is_lost_is_sent_once_and_settled_by_the_position(wheel):
    emu, drv = wheel(timeout_s=0.1, move_s=0.1)
    seen = spy_lines(emu)
    emu.server.faults = StallNext(1)
    drv.move_to_nm(532.0)  # taken; its reply lost: the position read back confirms it
    assert emu.position == 2 and drv.wavelength_nm() == 532.0
    assert seen.count("pos=2") == 1
    emu.server.faults = GarbleNext(1)
    drv.move_to_nm(632.8)  # taken; its reply garbled
    assert emu.position == 4 and seen.count("pos=4") == 1
    assert drv.line_counts()["resyncs"] >= 1


def test_a_move_the_wheel_never_took_is_an_error_and_not_resent(wheel):
    emu, drv = wheel(timeout_s=0.1, move_s=0.1)
    handle = emu.server.handler
    emu.server.handler = lambda line: None if line == b"pos=2" else handle(line)  # lost
    seen = spy_lines(emu)
    with pytest.raises(DriverError, match=r"fw102c: 'pos=2' not confirmed .*; not re-sent"):
        drv.move_to_nm(532.0)
    assert seen.count("pos=2") == 1 and emu.position == 1


def test_garbled_and_stalled_queries_are_asked_again_and_never_misread(wheel):
    emu, drv = wheel(timeout_s=0.1, retries=8)
    drv.move_to_position(4)
    assert read_through_faults(emu, drv.position, 40, seed=9) == [4] * 40
    emu.server.faults = FaultInjector(FaultSpec(stall_prob=1.0))
    with pytest.raises(DeviceTimeout, match="fw102c: timeout after 0.1 s"):
        drv.position()


def test_a_12_position_wheel_asks_again_when_a_dropped_digit_could_read_as_1_or_2(wheel):
    emu, drv = wheel(positions=12, filters=[(12, 700.0, 10.0), (1, 400.0, 10.0)])
    drv.move_to_nm(700.0)
    seen = spy_lines(emu)
    emu.server.faults = DropDigitOnce()
    assert drv.position() == 12  # 2, then 12 and 12: two that agree
    assert seen == ["pos?", "pos?", "pos?"]
    emu.server.faults = DropDigitEvery()
    with pytest.raises(ProtocolError, match=r"fw102c: pos\? answered 12, then 2"):
        drv.position()
    emu.server.faults = FaultInjector(FaultSpec())
    assert drv.position() == 12 and drv.wavelength_nm() == 700.0


def test_pylablib_drives_the_emulated_wheel(opened):
    thorlabs = pytest.importorskip("pylablib.devices.Thorlabs")
    emu = Fw102cEmulator(VirtualClock(math.inf))
    emu.start()
    opened.append(emu)
    client = thorlabs.FW((emu.endpoint, 115200))
    opened.append(client)
    assert client.get_pcount() == 6
    assert client.get_id() == IDN
    assert client.set_position(4) == 4 and emu.position == 4
    assert client.set_position(1) == 1 and emu.position == 1
    client.set_speed_mode("low")
    assert client.get_speed_mode() == "low" and emu.settings["speed"] == 0
    client.set_sensor_mode("on")
    assert client.get_sensor_mode() == "on"
    client.store_settings()
    assert emu.saved["sensors"] == 1
