"""The Newport Cornerstone 130 / 260 monochromator: its emulator against the manuals' exchanges
(echo, answers, error code and status byte) over a real pty, move times on the virtual clock,
the driver (wavelength, grating, shutter), device errors, and lost and garbled replies (a
command sent once and settled by a read-back, queries asked again)."""

import math

import pytest
from reply_faults import GarbleNext, StallNext, read_through_faults, spy_lines

from drivers.base import DeviceError, DriverError, WavelengthSelector
from drivers.cornerstone import CornerstoneMonochromator
from sim.devices.cornerstone import (
    GRATING_CHANGE_S,
    WAVE_SPEED_NM_S,
    CornerstoneConfigError,
    CornerstoneEmulator,
)
from sim.devices.faults import FaultSpec
from sim.devices.motion import VirtualClock


@pytest.fixture
def mono(start_pair):
    """make(faults=None, **driver options) -> (emulator, driver) on an instant clock."""

    def make(faults=None, timeout_s=0.3, retries=2, **options):
        emu = CornerstoneEmulator(VirtualClock(math.inf),
                                  faults=FaultSpec(**faults) if faults else None, seed=2)
        return start_pair(emu, CornerstoneMonochromator, timeout_s=timeout_s, retries=retries,
                          **options)

    return make


@pytest.fixture
def rs232(plain_port):
    """start(**emulator options) -> (emulator, port): the monochromator on a pty and a plain
    pyserial session with it."""

    def start(**options):
        emu = CornerstoneEmulator(VirtualClock(math.inf), **options)
        return emu, plain_port(emu, 9600)

    return start


def test_statements_are_echoed_and_queries_answered_as_the_manuals_show(rs232):
    emu, port = rs232()
    # the 130B manual's example, CR LF sent: GOWAVE 500[cr][lf] echoes GOWAVE 500[cr][lf]
    port.write(b"GOWAVE 500\r\n")
    assert port.readline() == b"GOWAVE 500\r\n"
    # the 260 manual's, LF alone: WAVE?[lf] gives WAVE?[lf]500[cr][lf]
    port.write(b"WAVE?\n")
    assert port.readline() + port.readline() == b"WAVE?\n500\r\n"
    port.write(b"gowave 632.8\n")  # any case
    assert port.readline() == b"gowave 632.8\n"
    port.write(b"wave?\n")
    assert port.readline() + port.readline() == b"wave?\n632.8\r\n"
    for query, answer in (("GRAT?", b"1,1200,1200 L/MM BLZ=500NM"), ("SHUTTER?", b"C"),
                          ("UNITS?", b"NM"), ("INFO?", b"CS130B V2.00"), ("STEP?", b"63280"),
                          ("ERROR?", b"0"), ("STB?", b"0")):
        port.write(query.encode() + b"\n")
        assert port.readline() + port.readline() == query.encode() + b"\n" + answer + b"\r\n"


def ask(port, query):
    """A query's answer, its echo read first."""
    port.write(query.encode() + b"\n")
    assert port.readline() == query.encode() + b"\n"
    return port.readline().decode().rstrip("\r\n")


@pytest.mark.parametrize("statement, code", [
    ("BOGUS", 1), ("WAVE? 5", 1), ("GOWAVE abc", 2), ("GOWAVE", 2), ("GRAT 4", 2),
    ("SHUTTER X", 2), ("UNITS FT", 2), ("GOWAVE 2000", 3), ("GOWAVE -1", 3), ("FILTER 2", 6),
    ("FILTER?", 6)])
def test_errors_set_the_code_and_status_byte_which_reading_clears(rs232, statement, code):
    emu, port = rs232()
    port.write(statement.encode() + b"\n")
    assert port.readline() == statement.encode() + b"\n"  # a command has no answer
    assert ask(port, "STB?") == "32" and ask(port, "STB?") == "0"
    assert ask(port, "ERROR?") == str(code) and ask(port, "ERROR?") == "0"
    assert emu.wavelength_nm == 500.0 and emu.grating == 1 and emu.moves == 0


def test_units_step_and_gratings(rs232):
    emu, port = rs232()
    for statement in ("UNITS UM", "GOWAVE 0.55", "UNITS WN"):
        port.write(statement.encode() + b"\n")
        port.readline()
    assert emu.wavelength_nm == pytest.approx(550.0)
    assert ask(port, "WAVE?") == "18181.818" and ask(port, "UNITS?") == "WN"
    for statement in ("UNITS NM", "STEP -100", "GRAT 2", "SHUTTER O"):
        port.write(statement.encode() + b"\n")
        port.readline()
    assert ask(port, "WAVE?") == "549" and ask(port, "STEP?") == "27450"
    assert ask(port, "GRAT?") == "2,600,600 L/MM BLZ=1000NM" and ask(port, "SHUTTER?") == "O"
    assert ask(port, "ERROR?") == "0"


def test_moves_take_their_time_and_the_next_statement_waits_for_them(rs232):
    emu, port = rs232()
    start = emu.clock.now()
    port.write(b"GOWAVE 700\n")
    assert port.readline() == b"GOWAVE 700\n"
    assert ask(port, "WAVE?") == "700"  # answered once the drive is there
    assert emu.clock.now() - start == pytest.approx(200.0 / WAVE_SPEED_NM_S)
    port.write(b"GRAT 2\n")
    port.readline()
    assert ask(port, "GRAT?").startswith("2,")
    assert emu.clock.now() - start == pytest.approx(2.0 + GRATING_CHANGE_S)
    port.write(b"GOWAVE 900\n")  # a 600 lines/mm grating: half the turn for 200 nm
    port.readline()
    assert ask(port, "ERROR?") == "0"
    assert emu.clock.now() - start == pytest.approx(3.0 + GRATING_CHANGE_S)


def test_the_emulator_refuses_a_set_up_it_cannot_have():
    with pytest.raises(CornerstoneConfigError, match="grating must be 1..2, got 3"):
        CornerstoneEmulator(grating=3)
    with pytest.raises(CornerstoneConfigError, match="2000.0 nm is beyond grating 1"):
        CornerstoneEmulator(wavelength_nm=2000.0)


def test_the_driver_selects_wavelength_grating_and_shutter(mono):
    emu, drv = mono(grating=2)
    assert isinstance(drv, WavelengthSelector)
    assert drv.identity() == {"info": "CS130B V2.00"}
    assert drv.grating() == (2, 600.0, "600 L/MM BLZ=1000NM") and emu.grating == 2
    drv.move_to_nm(1550.0)
    assert drv.wait(30.0) == 1550.0 and emu.wavelength_nm == 1550.0
    drv.open_shutter(True)
    assert drv.shutter_open() and emu.shutter_open
    drv.open_shutter(False)
    assert not emu.shutter_open
    with pytest.raises(DeviceError, match="device error 3"):
        drv.select_grating(1)  # 1550 nm is beyond the 1200 lines/mm grating: refused
    assert emu.grating == 2 and drv.grating()[0] == 2


def test_a_wavelength_the_grating_cannot_reach_is_the_devices_error_3(mono):
    emu, drv = mono()
    drv.move_to_nm(1500.0)
    with pytest.raises(DeviceError, match="cornerstone: device error 3: destination position "
                                          "for wavelength motion not allowed"):
        drv.wait(10.0)
    assert drv.wavelength_nm() == 500.0
    with pytest.raises(ValueError, match="wavelength must be > 0 nm"):
        drv.move_to_nm(0.0)


def test_a_lost_error_code_is_settled_by_the_read_back_and_nothing_is_resent(mono):
    emu, drv = mono(timeout_s=0.1)
    seen = spy_lines(emu)
    drv.move_to_nm(600.0)
    emu.server.faults = StallNext(1)  # ERROR?'s answer lost
    assert drv.wait(0.1) == 600.0
    emu.server.faults = GarbleNext(1)  # the shutter command's echo garbled
    drv.open_shutter(True)  # taken: SHUTTER? read back confirms it
    assert emu.shutter_open
    assert seen.count("GOWAVE 600.000\r") == 1 and seen.count("SHUTTER O\r") == 1
    assert drv.shutter_open() and drv.line_counts()["resyncs"] >= 1


def test_a_move_whose_error_code_is_lost_and_not_taken_is_an_error(mono):
    emu, drv = mono(timeout_s=0.1)
    drv.move_to_nm(1500.0)  # beyond grating 1: refused, and the code that says so is lost
    emu.server.faults = StallNext(1)
    with pytest.raises(DriverError, match=r"'GOWAVE 1500.000' not taken: the drive is at 500 "
                                          "nm; not re-sent"):
        drv.wait(0.1)
    assert emu.wavelength_nm == 500.0


def test_a_statement_the_device_never_got_has_no_echo(mono):
    emu, drv = mono(timeout_s=0.1)
    handle = emu.server.handler
    emu.server.handler = lambda line: None if line.startswith(b"GOWAVE") else handle(line)
    seen = spy_lines(emu)
    drv.move_to_nm(600.0)  # no echo: wait() settles it by the drive read back
    with pytest.raises(DriverError, match="'GOWAVE 600.000' not taken: the drive is at 500"):
        drv.wait(0.1)
    assert drv.wavelength_nm() == 500.0 and seen.count("GOWAVE 600.000\r") == 1
    emu.server.handler = handle
    drv.select_grating(2)
    emu.server.handler = lambda line: None if line.startswith(b"GRAT 1") else handle(line)
    with pytest.raises(DriverError, match=r"'GRAT 1' not confirmed \(.*echo of 'GRAT 1'.*\); "
                                          "not re-sent"):
        drv.select_grating(1)
    assert emu.grating == 2


def test_garbled_and_stalled_queries_are_asked_again_and_never_misread(mono):
    emu, drv = mono(timeout_s=0.1, retries=8)
    drv.move_to_nm(632.8)
    drv.wait(10.0)
    assert read_through_faults(emu, drv.wavelength_nm, 40, seed=5) == [632.8] * 40
