"""The ESP301 manual's own examples (EDH0235En1030, section 3), sent as bytes over a real pty
to the emulator, and the commands a motion client uses beyond gonio's driver: desired
position and velocity, maximum speed and acceleration, waits, home preset, stored settings.
Numbers come back with the emulator's 5 decimals where the manual prints fewer."""

import math

import pytest
import serial
from ticking_clock import TickingClock

from sim.devices.esp import EspEmulator
from sim.devices.motion import VirtualClock

WIDE = {"limits_deg": (-1000.0, 1000.0)}


@pytest.fixture
def esp():
    """esp(time_scale=inf, axes=None, clock=None) -> (emulator, send): send(line) -> reply
    text or None."""
    opened = []

    def make(time_scale=math.inf, axes=None, clock=None):
        emu = EspEmulator(clock or VirtualClock(time_scale), axes or {1: dict(WIDE), 2: dict(WIDE),
                                                             3: dict(WIDE)})
        emu.start()
        port = serial.Serial(emu.endpoint, 19200, timeout=2.0)
        opened.append((emu, port))

        def send(line: str) -> str | None:
            """Send one command line; its reply, or None for a silent line (checked with a
            trailing VE? that must come back alone)."""
            port.write(f"{line};VE?\r".encode())
            reply = port.read_until(b"\r\n").decode()
            assert reply.endswith("ESP301 Version 3.0.2 (emulated)\r\n"), reply
            head = reply[: -len("ESP301 Version 3.0.2 (emulated)\r\n")]
            return head.rstrip(",") or None

        return emu, send

    yield make
    for emu, port in opened:
        port.close()
        emu.stop()
        assert emu.server.handler_errors == []


def errors(send) -> list[str]:
    """Drain the error buffer with TB?: the (code, message) texts."""
    found = []
    while not (status := send("TB?")).startswith("0, "):
        code, _, text = status.split(", ")
        found.append(f"{code} {text}")
    return found


def test_remote_mode_example_move_wait_then_move_the_next_axis(esp):
    """3.2, example 2: `1PA+30; 1WS; 2PR-10` (semicolons in place of carriage returns)."""
    emu, send = esp()
    send("1MO;2MO")
    assert send("1PA+30; 1WS; 2PR-10") is None
    assert send("1TP?;2DP?") == "30.00000,-10.00000"
    assert errors(send) == []


def test_command_syntax_examples(esp):
    """3.4: `3PA10.0`, `3WS`, `AB`, `3MO; 3PA10.0; 3WS; 3MF`; blanks are ignored
    (`2 PA 1000` = `2PA1000`); `BO1` and `1HN1,2` are real commands the emulator does not
    model (DIO, groups): 27 COMMAND NOT ALLOWED, never 6."""
    emu, send = esp()
    assert send("3MO; 3PA10.0; 3WS; 3MF") is None
    assert send("3TP?;3MO?") == "10.00000,0"
    send("2MO")
    assert send("2 PA 1000;2WS") is None
    assert emu.axis_position_deg(2) == 1000.0
    assert send("AB;BO1;1HN1,2;1QQ") is None
    assert errors(send) == ["27 COMMAND NOT ALLOWED", "27 COMMAND NOT ALLOWED",
                            "6 COMMAND DOES NOT EXIST"]


def test_dp_example_desired_position_is_where_the_move_ends(esp):
    """DP (p. 3-52): `3TP?` 5.32, `3PR2.2`, `3DP?` 7.52 (the axis still at 5.32)."""
    emu, send = esp(time_scale=0.0)  # frozen: the move has not begun
    send("3MO;3DH5.32")
    assert send("3TP?") == "5.32000"
    assert send("3PR2.2") is None
    assert send("3DP?") == "7.52000"
    assert send("3TP?") == "5.32000"


def test_tv_example_desired_and_actual_velocity_while_moving(esp):
    """TV (p. 3-143 of the ESP300 manual, same command): `3PR2.2` at 0.2 units/s, `3DV` 0.2,
    `3TV` 0.205 on a real servo (the emulated one follows its profile: 0.2), `3DP?` 7.52."""
    emu, send = esp(time_scale=0.0)
    send("3MO;3DH5.32;3VA0.2;3AC0.8;3AG0.8")
    assert send("3DV;3TV") == "0.00000,0.00000"
    send("3PR2.2")
    emu.clock.advance(1.0)  # past the 0.25 s ramp: cruising
    assert send("3DV") == "0.20000"
    assert send("3TV") == "0.20000"
    assert send("3DP?") == "7.52000"
    send("3PR-4")  # a move the other way: velocities are signed
    emu.clock.advance(2.0)
    assert send("3DV?;3TV?") == "-0.20000,-0.20000"


def test_mv_example_move_indefinitely_query_stop_reverse(esp):
    """MV (p. 3-101 of the ESP300 manual): `3MV+`, `3MV?` 0 (in progress), `3ST`, `3MV-`;
    the emulated stage runs until a stop or its software limit."""
    emu, send = esp(time_scale=0.0)
    send("3MO;3VA10;3AC100;3AG100")
    assert send("3MV+") is None
    emu.clock.advance(1.0)
    assert send("3MV?") == "0"
    assert send("3ST") is None
    emu.clock.advance(1.0)
    assert send("3MD?") == "1"
    stopped = float(send("3TP?"))
    assert 0.0 < stopped < 1000.0
    assert send("3MV-") is None
    emu.clock.advance(500.0)
    assert send("3MV?;3TP?") == "1,-1000.00000"
    assert send("3MVX;3MV") is None
    assert errors(send) == ["301 PARAMETER OUT OF RANGE", "38 COMMAND PARAMETER MISSING"]


def test_id_example_stage_model_and_serial(esp):
    """ID (p. 3-86 of the ESP300 manual): `1ID?` answers `TS50DC.5, SN1263`."""
    emu, send = esp(axes={1: {"stage_id": "TS50DC.5, SN1263"}, 2: {}})
    assert send("1ID?") == "TS50DC.5, SN1263"
    assert send("2ID?") == "ROTARY-EMU, SN0002"
    assert send("1IDMYSTAGE") is None  # writing a custom ID is not emulated
    assert errors(send) == ["27 COMMAND NOT ALLOWED"]


def test_tb_example_error_message_with_timestamp(esp):
    """TB: an error is read back as `code, timestamp, MESSAGE` and then it is gone."""
    emu, send = esp()
    send("7TP?")
    code, stamp, text = send("TB?").split(", ")
    assert (code, text) == ("9", "AXIS NUMBER OUT OF RANGE") and stamp.isdigit()
    assert send("TE?") == "0"


def test_vu_and_au_bound_velocity_and_acceleration(esp):
    """VU / AU: the maximum speed and acceleration; VA, AC, AG above them are x10 / x11;
    a lower VU or AU brings VA, the jog and home speeds, AC and AG down to it."""
    emu, send = esp()
    assert send("1VU?;1AU?") == "200.00000,2000.00000"
    send("1VU50;1AU400")
    assert send("1VU?;1AU?") == "50.00000,400.00000"
    assert send("1VA60;1AC500;1AG401") is None
    assert errors(send) == ["110 MAXIMUM VELOCITY EXCEEDED", "111 MAXIMUM ACCELERATION EXCEEDED",
                            "111 MAXIMUM ACCELERATION EXCEEDED"]
    send("1VA40;1JH45;1AC300")
    send("1VU30;1AU100")
    assert send("1VA?;1JH?;1AC?;1AG?") == "30.00000,30.00000,100.00000,80.00000"
    assert send("1VU0;1AU-1;1VU3e9") is None
    assert errors(send) == ["101 PARAMETER OUT OF RANGE"] * 3
    send("1SN9")  # radians: the limits are shown in the axis's units too
    assert send("1VU?") == f"{math.radians(30.0):.5f}"


def test_wp_holds_the_line_until_the_position_is_crossed(esp):
    """WP x: the rest of the line runs once the axis has crossed x; x outside the motion's
    span (start to destination) is x01."""
    emu, send = esp(clock=TickingClock(0.05))  # each look at the clock moves it 50 ms on
    send("1MO;1VA20;1AC80")
    reply = send("1PA100;1WP40;1TP?")
    assert 40.0 <= float(reply) < 42.0  # crossed 40 a few clock reads ago, on its way to 100
    assert send("1DP?") == "100.00000"
    assert send("1WP120;1WS;1WP10") is None
    assert errors(send) == ["101 PARAMETER OUT OF RANGE", "101 PARAMETER OUT OF RANGE"]
    assert send("1WP100;1TP?") == "100.00000"  # at rest on the mark: no wait


def test_wt_waits_virtual_time_within_the_manuals_range(esp):
    """WT ms: 0 to 60000 ms of (virtual) time; out of range is 7."""
    emu, send = esp()
    t0 = emu.clock.now()
    assert send("WT1500") is None
    assert emu.clock.now() - t0 == pytest.approx(1.5)
    assert send("WT60001;WT-1") is None
    assert errors(send) == ["7 PARAMETER OUT OF RANGE"] * 2


def test_home_search_uses_the_mode_speed_and_preset(esp):
    """OM, OH, SH: OR without a mode takes OM's; the search runs at OH and ends at the SH
    preset, which must lie within the travel; DH? reads back the last defined home."""
    emu, send = esp(axes={1: {"limits_deg": (-90.0, 90.0)}})
    send("1MO;1PA50;1WS")
    send("1OM2;1OH10;1SH-20")
    assert send("1OM?;1OH?;1SH?") == "2,10.00000,-20.00000"
    t0 = emu.clock.now()
    send("1OR;1WS")
    assert send("1TP?;1MD?") == "-20.00000,1"
    assert emu.clock.now() - t0 == pytest.approx(70.0 / 10.0 + 10.0 / 80.0)  # at OH 10 deg/s
    assert send("1SH95;1OR9;1OH300") is None
    assert errors(send) == ["101 PARAMETER OUT OF RANGE"] * 2 + ["110 MAXIMUM VELOCITY EXCEEDED"]
    send("1DH12.5")
    assert send("1DH?;1TP?") == "12.50000,12.50000"


@pytest.mark.parametrize("name, value, shown", [
    ("FE", "0.5", "0.50000"), ("SU", "0.0005", "0.00050"), ("FR", "0.01", "0.01000"),
    ("BA", "0.1", "0.10000"), ("JH", "15", "15.00000"), ("JW", "1.5", "1.50000"),
    ("JK", "800", "800.00000"), ("OL", "2", "2.00000"), ("VB", "1", "1.00000"),
    ("AE", "500", "500.00000"), ("AF", "3e-1", "0.30000"), ("CO", "0.001", "0.00100"),
    ("KP", "40", "40.00000"), ("KI", "2", "2.00000"), ("KD", "300", "300.00000"),
    ("KS", "0.5", "0.50000"), ("VF", "0", "0.00000"), ("QG", "2", "2.00000"),
    ("QT", "20", "20.00000"), ("QI", "0.8", "0.80000"), ("QV", "24", "24.00000"),
    ("QM", "2", "2"), ("QS", "250", "250"), ("FP", "3", "3"), ("CL", "100", "100"),
    ("DB", "2", "2"), ("TJ", "1", "1"), ("ZB", "0123H", "123H"), ("ZH", "36", "24H"),
    ("ZA", "0FFFFH", "FFFFH"), ("ZE", "0", "0H"), ("ZF", "1H", "1H"), ("ZS", "5", "5H"),
])
def test_stored_settings_read_back_in_the_axis_units(esp, name, value, shown):
    """Settings that configure hardware the emulator idealises are kept and read back;
    position-like ones follow SN (here gradians after degrees)."""
    emu, send = esp()
    assert send(f"2{name}{value}") is None
    assert send(f"2{name}?") == shown
    assert errors(send) == []


@pytest.mark.parametrize("line, error", [
    ("2QM5", "201 PARAMETER OUT OF RANGE"), ("2QS0", "201 PARAMETER OUT OF RANGE"),
    ("2FP8", "201 PARAMETER OUT OF RANGE"), ("2QM1.5", "201 PARAMETER OUT OF RANGE"),
    ("2ZB10000H", "201 PARAMETER OUT OF RANGE"), ("2KP-1", "201 PARAMETER OUT OF RANGE"),
    ("2KP3e9", "201 PARAMETER OUT OF RANGE"), ("2QT21", "201 PARAMETER OUT OF RANGE"),
    ("2SU0", "201 PARAMETER OUT OF RANGE"), ("2AE10", "201 PARAMETER OUT OF RANGE"),
    ("2BA2", "201 PARAMETER OUT OF RANGE"), ("2JH250", "210 MAXIMUM VELOCITY EXCEEDED"),
    ("2TJ2", "27 COMMAND NOT ALLOWED"), ("2KP", "38 COMMAND PARAMETER MISSING"),
    ("2KPx", "7 PARAMETER OUT OF RANGE"), ("KP1", "37 AXIS NUMBER MISSING"),
])
def test_stored_settings_refuse_values_outside_the_manuals_ranges(esp, line, error):
    """Out of range is x01 (x10 for a speed above VU); AE may not be below AG; BA at most
    10000 encoder counts (SU); TJ other than 1 (trapezoidal) is not emulated."""
    emu, send = esp()
    before = send(f"{line[:3]}?") if line[0] == "2" and line[1:3].isalpha() else None
    assert send(line) is None
    assert errors(send) == [error]
    if before is not None:
        assert send(f"{line[:3]}?") == before  # nothing changed


def test_stored_position_settings_follow_the_units(esp):
    emu, send = esp()
    send("2FE0.9;2JH18;2SN8")
    assert send("2FE?;2JH?;2SN?") == "1.00000,20.00000,8"


def test_update_and_save_commands_are_accepted(esp):
    """UF, QD (every axis without a number) and SM are accepted: there is nothing for the
    emulated servo or driver to load, and settings last as long as the emulator."""
    emu, send = esp()
    assert send("UF;1UF;QD;2QD;SM") is None
    assert errors(send) == []
