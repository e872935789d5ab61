"""Zaber ASCII protocol: the emulator answering the manual's message strings over a plain
pyserial session, the emulator's table checks, and the driver's sans-I/O reply reader."""

import math

import pytest
import serial

from drivers.base import ProtocolError
from drivers.zaber import lrc, parse_reply
from sim.devices.motion import VirtualClock
from sim.devices.zaber import ZaberConfigError, ZaberEmulator


@pytest.fixture
def port():
    """A pyserial session with a two-device chain: device 1 (two axes), device 2 (one)."""
    axes = {(1, 1): {"limits_deg": (-90, 90)}, (1, 2): {"homed": False}, (2, 1): {}}
    with ZaberEmulator(VirtualClock(math.inf), axes) as emu, \
            serial.Serial(emu.endpoint, 115200, timeout=0.2) as session:
        session.emulator = emu
        yield session
    assert emu.server.handler_errors == []


def ask(session, command: str) -> list[str]:
    """Send one command (CR LF) and collect every line that comes back."""
    session.write(command.encode("ascii") + b"\r\n")
    lines = [session.read_until(b"\r\n")]  # the emulator writes all its lines at once
    while session.in_waiting:
        lines.append(session.read_until(b"\r\n"))
    return [line.decode("ascii").removesuffix("\r\n") for line in lines if line]


def test_replies_carry_scope_status_flag_and_data(port):
    assert ask(port, "/1 1 move abs 1000") == ["@01 1 OK IDLE -- 0"]
    assert ask(port, "/1 1 get pos") == ["@01 1 OK IDLE -- 1000"]
    assert ask(port, "/1 0 get pos") == ["@01 0 OK IDLE WR 1000 0"]  # axis 2 is not homed
    assert ask(port, "/1 2 home") == ["@01 2 OK IDLE -- 0"]
    assert ask(port, "/1") == ["@01 0 OK IDLE -- 0"]
    assert ask(port, "/1 1 12 get maxspeed") == ["@01 1 12 OK IDLE -- 139810"]  # 20 deg/s
    assert ask(port, "/1 1 get accel") == ["@01 1 OK IDLE -- 56"]  # 80 deg/s^2
    assert ask(port, "/1 1 get resolution") == ["@01 1 OK IDLE -- 64"]
    assert ask(port, "/get system.serial") == ["@01 0 OK IDLE -- 120001",
                                              "@02 0 OK IDLE -- 120002"]  # every device
    assert ask(port, "/9 get pos") == []  # nobody has address 9


@pytest.mark.parametrize("command, reason", [
    ("/1 3 get pos", "BADAXIS"),
    ("/1 1 frobnicate", "BADCOMMAND"),
    ("/1 1 get nonsense", "BADCOMMAND"),
    ("/1 1 set resolution 32", "BADCOMMAND"),  # read-only here
    ("/1 set version 8", "BADCOMMAND"),
    ("/1 1 move abs 400000", "BADDATA"),  # beyond limit.max (90 deg = 384000)
    ("/1 1 move abs 1.5", "BADDATA"),
    ("/1 1 set maxspeed 0", "BADDATA"),
    ("/1 1 set limit.min 999999999", "BADDATA"),  # not below limit.max
    ("/1 set comm.alert 2", "BADDATA"),
    ("/1 1 get version", "DEVICEONLY"),
    ("/1 set version.build 1", "BADCOMMAND"),  # the identity settings are read-only
    ("/1 set comm.packet.size.max 200", "BADCOMMAND"),
    ("/1 set comm.checksum yes", "BADDATA"),
    ("/1 1 get deviceid", "DEVICEONLY"),
    ("/1 1 system reset", "DEVICEONLY"),
    ("/1 system restore", "BADCOMMAND"),  # not emulated
    ("/1 1 get peripheralid", "BADCOMMAND"),  # an integrated product has no peripheral
])
def test_rejections_name_the_manuals_reason(port, command, reason):
    axis = command.split()[1] if command.split()[1].isdigit() else "0"
    flag = "--" if axis == "1" else "WR"  # a device-scope reply shows axis 2's flag
    assert ask(port, command) == [f"@01 {axis} RJ IDLE {flag} {reason}"]


def test_identity_settings_a_client_reads_while_it_detects_devices(port):
    expected = {"deviceid": "50001", "version": "7.38", "version.build": "12870",
                "system.serial": "120001", "system.axiscount": "2", "device.hw.modified": "0",
                "comm.address": "1", "comm.rs232.baud": "115200", "comm.packet.size.max": "80",
                "comm.command.packets.max": "1", "comm.word.size.max": "80",
                "get.settings.max": "1", "comm.alert": "0", "comm.checksum": "0"}
    for name, value in expected.items():
        assert ask(port, f"/1 get {name}") == [f"@01 0 OK IDLE WR {value}"], name
    assert ask(port, "/2 get system.axiscount") == ["@02 0 OK IDLE -- 1"]
    assert ask(port, "/1 0 get resolution") == ["@01 0 OK IDLE WR 64 64"]  # one per axis


def test_a_product_reports_its_own_identity():
    with ZaberEmulator(VirtualClock(math.inf), {1: {}}, device_id=50419, firmware="7.33") \
            as emu, serial.Serial(emu.endpoint, 115200, timeout=0.2) as session:
        assert ask(session, "/get deviceid") == ["@01 0 OK IDLE -- 50419"]
        assert ask(session, "/get version") == ["@01 0 OK IDLE -- 7.33"]


def test_bad_message_id_and_busy_rejections(port):
    assert ask(port, "/1 1 100 get pos") == ["@01 1 RJ IDLE -- BADMESSAGEID"]
    port.emulator.clock.time_scale = 1.0  # let the next move take (real) time
    assert ask(port, "/1 1 move abs 300000")[0] == "@01 1 OK BUSY -- 0"
    assert ask(port, "/1 1 set pos 0") == ["@01 1 RJ BUSY -- STATUSBUSY"]
    assert ask(port, "/1 1 stop") == ["@01 1 OK BUSY NI 0"]  # interrupted, decelerating


def test_checksums_both_ways(port):
    body = "1 1 get pos"
    assert ask(port, f"/{body}:{lrc(body)}") == ["@01 1 OK IDLE -- 0"]
    assert ask(port, f"/{body}:00") == []  # a wrong checksum: dropped unanswered
    assert ask(port, "/1 set comm.checksum 1") == ["@01 0 OK IDLE WR 0:3E"]
    reply = ask(port, "/1 1 get limit.max")[0]
    text, cc = reply.rsplit(":", 1)
    assert text == "@01 1 OK IDLE -- 384000" and cc == lrc(text[1:])
    assert lrc("1") == "CF" and lrc("") == "00"  # the LRC: -(byte sum) mod 256


def test_alerts_tell_a_motion_ended(port):
    port.emulator.clock.time_scale = 0.0  # frozen: the move ends when the test moves time on
    assert ask(port, "/1 set comm.alert 1") == ["@01 0 OK IDLE WR 0"]
    ask(port, "/1 1 move rel 500")
    port.emulator.clock.advance(60.0)
    assert ask(port, "/1 1 get pos") == ["!01 1 IDLE --", "@01 1 OK IDLE -- 500"]
    assert ask(port, "/1 1 get pos") == ["@01 1 OK IDLE -- 500"]  # once per motion


def test_warnings_list_and_clear(port):
    port.emulator.raise_fault((1, 1), "FS")
    assert ask(port, "/1 warnings") == ["@01 0 OK IDLE FS 02 FS WR"]
    assert ask(port, "/1 1 warnings clear") == ["@01 1 OK IDLE -- 01 FS"]  # listed, cleared
    assert ask(port, "/1 1 warnings") == ["@01 1 OK IDLE -- 00"]
    with pytest.raises(ValueError, match="a fault flag"):
        port.emulator.raise_fault((1, 1), "WR")


def test_device_scope_motion_moves_every_axis(port):
    assert ask(port, "/1 0 move abs 2000") == ["@01 0 OK IDLE WR 0"]
    assert ask(port, "/1 0 get pos") == ["@01 0 OK IDLE WR 2000 2000"]
    assert ask(port, "/1 0 home") == ["@01 0 OK IDLE -- 0"]
    assert ask(port, "/1 0 get pos") == ["@01 0 OK IDLE -- 0 0"]
    assert ask(port, "/1 0 move max") == ["@01 0 OK IDLE -- 0"]
    assert ask(port, "/1 1 get pos") == ["@01 1 OK IDLE -- 384000"]


@pytest.mark.parametrize("table, message", [
    ({1: {"speed": 3}}, r"zaber device 1 axis 1: unknown key 'speed'"),
    ({1: {"resolution": 0}}, r"resolution must be an integer >= 1"),
    ({1: {"speed_deg_s": "fast"}}, r"speed_deg_s must be a number"),
    ({1: {"speed_deg_s": 500.0}}, r"within max_speed/max_accel"),
    ({1: {}, 3: {}}, r"zaber device 1: axes must be numbered 1..n"),
    ({(100, 1): {}}, r"device addresses are 1..99"),
    ({}, r"at least one axis"),
])
def test_emulator_tables_are_checked(table, message):
    with pytest.raises(ZaberConfigError, match=message):
        ZaberEmulator(VirtualClock(math.inf), table)


@pytest.mark.parametrize("identity, message", [
    ({"device_id": "50419"}, "zaber: device_id: must be a positive integer (the product's "
                             "Zaber device id), got '50419'"),
    ({"device_id": 0}, "zaber: device_id: must be a positive integer (the product's Zaber "
                       "device id), got 0"),
    ({"device_id": True}, "zaber: device_id: must be a positive integer (the product's Zaber "
                          "device id), got True"),
    ({"firmware": 7.38}, 'zaber: firmware: must be a firmware-7 version such as "7.38" (the '
                         'protocol emulated), got 7.38'),
    ({"firmware": "6.32"}, 'zaber: firmware: must be a firmware-7 version such as "7.38" (the '
                           "protocol emulated), got '6.32'"),
    ({"alerts": 1}, "zaber: alerts: must be true or false (the comm.alert the device saved), "
                    "got 1"),
])
def test_the_products_identity_is_checked(identity, message):
    with pytest.raises(ZaberConfigError) as err:
        ZaberEmulator(VirtualClock(math.inf), {1: {}}, **identity)
    assert str(err.value) == message


def reply(body: str) -> str:
    return f"@{body}:{lrc(body)}"


def test_parse_reply_reads_every_field():
    got = parse_reply(reply("02 1 07 OK BUSY NI 1234"), 2, 1, 7, checksummed=True)
    assert (got.flag, got.status, got.warning, got.data, got.busy) == \
        ("OK", "BUSY", "NI", "1234", True)
    assert parse_reply("@02 1 07 RJ IDLE -- BADDATA", 2, 1, 7, checksummed=False).data == \
        "BADDATA"


@pytest.mark.parametrize("text, problem", [
    ("@01 1 07 OK IDLE -- 1234", "fails its checksum"),  # checksums are on: one must be there
    (reply("01 1 07 OK IDLE -- 1234")[:-1], "fails its checksum"),
    (reply("01 1 07 OK IDLE -- 1234").replace("1234", "124"), "fails its checksum"),
    (reply("01 1 07 OK IDLE --  1234"), "a garbled reply"),
    (reply("01 1 07 OK WAIT -- 1234"), "a garbled reply"),
    (reply("01 1 OK IDLE -- 1234"), "a garbled reply"),  # no message id
    (reply("01 1 08 OK IDLE -- 1234"), "answers another request"),
    (reply("01 2 07 OK IDLE -- 1234"), "answers another request"),
    (reply("03 1 07 OK IDLE -- 1234"), "answers another request"),
    ("!" + reply("01 1 IDLE --")[1:], "an alert where a reply was due"),
    ("#" + reply("01 1 07 some info")[1:], "an info message where a reply was due"),
])
def test_parse_reply_refuses_anything_else(text, problem):
    with pytest.raises(ProtocolError, match=problem):
        parse_reply(text, 1, 1, 7, checksummed=True)
