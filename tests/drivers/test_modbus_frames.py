"""Modbus frames cut from raw bytes and sorted for the reply machine, and the RTU echo's answer
found in a byte stream: no transport, bytes built by hand (pymodbus's CRC)."""

import struct

import pytest
from pymodbus.framer import FramerRTU
from pymodbus.pdu import ExceptionResponse

from drivers.modbus_frames import Expected, cut_rtu, cut_tcp, sort_rtu, sort_tcp
from drivers.modbus_rtu_sync import EchoTokens, echo_answer_end, rtu_frame
from drivers.reply_sync import UnitKind

READ_REPLY = rtu_frame(1, bytes([3, 4, 0x12, 0x34, 0x56, 0x78]))  # two registers of unit 1
WRITE_REPLY = rtu_frame(1, bytes([16, 0, 8, 0, 2]))
EXCEPTION = rtu_frame(1, bytes([0x83, 2]))
READ = Expected(unit=1, function=3)


def crc_broken(frame: bytes) -> bytes:
    return frame[:-1] + bytes([frame[-1] ^ 0x5A])


def test_every_complete_frame_is_cut_and_a_partial_one_waits():
    data = READ_REPLY + WRITE_REPLY + READ_REPLY[:5]
    frames, used = cut_rtu(data)
    assert [f.raw for f in frames] == [READ_REPLY, WRITE_REPLY]
    assert used == len(READ_REPLY + WRITE_REPLY)
    assert frames[0].pdu.registers == [0x1234, 0x5678]


def test_noise_and_a_bad_crc_are_skipped_to_the_next_frame():
    frames, used = cut_rtu(b"\x00\xff" + crc_broken(WRITE_REPLY) + READ_REPLY)
    assert [f.raw for f in frames] == [READ_REPLY] and used == 2 + len(WRITE_REPLY) + 9
    frames, used = cut_rtu(crc_broken(READ_REPLY))
    assert frames == [] and used < len(READ_REPLY)  # its tail might start a frame: it waits
    frames, used = cut_rtu(crc_broken(READ_REPLY) + READ_REPLY)  # ... until a whole one comes
    assert [f.raw for f in frames] == [READ_REPLY] and used == 2 * len(READ_REPLY)


def test_rtu_frames_sorted_by_unit_function_and_echo():
    echo = rtu_frame(1, bytes([8, 0, 0, 0xAB, 0xCD]))
    no_diagnostics = rtu_frame(1, bytes([0x88, 1]))
    other_unit = rtu_frame(2, bytes([3, 4, 0, 0, 0, 0]))
    frames, _ = cut_rtu(READ_REPLY + EXCEPTION + WRITE_REPLY + echo + no_diagnostics
                        + other_unit)
    assert [sort_rtu(f, READ) for f in frames] == [
        (UnitKind.ANSWER, None), (UnitKind.ANSWER, None), (UnitKind.FOREIGN, None),
        (UnitKind.SYNC, b"\xab\xcd"), (UnitKind.SYNC, None), (UnitKind.FOREIGN, None)]
    assert isinstance(frames[1].pdu, ExceptionResponse) and frames[1].pdu.exception_code == 2


def mbap(tid: int, unit: int, pdu: bytes) -> bytes:
    return struct.pack(">HHHB", tid, 0, len(pdu) + 1, unit) + pdu


def test_tcp_frames_sorted_by_transaction_id():
    ours, late = mbap(7, 1, bytes([3, 2, 0, 5])), mbap(6, 1, bytes([3, 2, 0, 4]))
    wrong_function, undecodable = mbap(7, 1, bytes([4, 2, 0, 5])), mbap(7, 1, bytes([16, 0]))
    frames, used = cut_tcp(late + ours + wrong_function + undecodable + ours[:6])
    assert used == 3 * len(ours) + len(undecodable)
    expected = Expected(unit=1, function=3, tid=7)
    assert [sort_tcp(f, expected)[0] for f in frames] == [
        UnitKind.FOREIGN, UnitKind.ANSWER, UnitKind.GARBLED, UnitKind.GARBLED]
    assert frames[1].pdu.registers == [5]


@pytest.mark.parametrize("damage", ["none", "lost", "altered"])
def test_the_echo_answer_is_found_behind_late_frames(damage):
    token, echo = EchoTokens().next_echo(1)
    assert echo == rtu_frame(1, b"\x08\x00\x00" + token)
    answer = {"none": echo, "lost": echo[:3] + echo[4:],
              "altered": echo[:5] + bytes([echo[5] ^ 1]) + echo[6:]}[damage]
    data = READ_REPLY + crc_broken(READ_REPLY) + answer
    assert echo_answer_end(data, echo, 1) == len(data)
    assert echo_answer_end(READ_REPLY + answer[:-2], echo, 1) is None


def test_the_exception_reply_to_the_echo_counts_only_with_its_crc():
    token, echo = EchoTokens().next_echo(3)
    refused = rtu_frame(3, bytes([0x88, 1]))
    assert echo_answer_end(READ_REPLY + refused, echo, 3) == len(READ_REPLY + refused)
    assert echo_answer_end(crc_broken(refused), echo, 3) is None
    assert FramerRTU.check_CRC(refused[:-2], int.from_bytes(refused[-2:], "big"))
