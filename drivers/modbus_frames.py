"""Modbus reply frames cut from the bytes a link reads, and sorted for drivers.reply_sync: the
sans-I/O half of the Modbus link (drivers.modbus_transport does the reading and writing).

pymodbus 3.16 gives the codecs: its PDU decoder (which response class a function code has, how
long its RTU frame is, how to decode it), its RTU CRC and its TCP (MBAP) framer. Its own
receive loop keeps only one frame per read and reports a lost reply and a mismatched one as the
same exception told apart by its text; here every complete frame in the buffer is cut and
sorted by what it is, so the link never reads a timeout out of a message.
"""

from __future__ import annotations

from typing import NamedTuple

from pymodbus.framer import FramerRTU, FramerSocket
from pymodbus.pdu import DecodePDU, ExceptionResponse, ModbusPDU

from drivers.reply_sync import UnitKind

DIAGNOSTICS = 0x08  # the function of the resync echo (drivers.modbus_rtu_sync)
RTU_MIN_BYTES = 4  # unit id, function code, CRC
_decoder = DecodePDU(False)  # replies (the client side)


class Frame(NamedTuple):
    """One reply frame: the unit and transaction id it carries, its PDU (None: a frame of the
    right length and checksum whose content pymodbus cannot decode) and its bytes."""

    unit: int
    tid: int
    pdu: ModbusPDU | None
    raw: bytes


class Expected(NamedTuple):
    """What answers the request just sent: its unit, function code and transaction id (0 on
    RTU, whose frames carry none)."""

    unit: int
    function: int
    tid: int = 0


def cut_rtu(data: bytes) -> tuple[list[Frame], int]:
    """The complete RTU frames in data and how many bytes they (and the noise between them)
    used; the rest waits for more bytes. A byte that cannot start a frame (unknown function),
    a frame whose CRC fails, and a frame start still short of its length while a complete
    frame follows it are noise: the search goes on, as a master hunting for a frame does."""
    frames: list[Frame] = []
    start = 0
    while len(data) - start >= RTU_MIN_BYTES:
        size = _frame_size(data, start)
        if size > 0:
            body = data[start:start + size - 2]
            frames.append(Frame(body[0], 0, _decoder.decode(body[1:]), data[start:start + size]))
            start += size
        elif size == _NOISE:
            start += 1
        else:  # short: wait for the rest, unless a whole frame follows
            later = next((i for i in range(start + 1, len(data) - RTU_MIN_BYTES + 1)
                          if _frame_size(data, i) > 0), None)
            if later is None:
                break
            start = later
    return frames, start


_NOISE, _SHORT = 0, -1


def _frame_size(data: bytes, start: int) -> int:
    """The size of the CRC-checked frame at data[start:], _NOISE if none starts there, or
    _SHORT if one may, but its bytes have not all come."""
    rest = data[start:]
    cls = _decoder.lookupPduClass(rest)
    size = cls.calculateRtuFrameSize(rest) if cls is not None else 0
    if size < RTU_MIN_BYTES:
        return _NOISE
    if len(rest) < size:
        return _SHORT
    crc = int.from_bytes(rest[size - 2:size], "big")
    return size if FramerRTU.check_CRC(rest[:size - 2], crc) else _NOISE


def cut_tcp(data: bytes) -> tuple[list[Frame], int]:
    """The complete MBAP frames at the front of data and how many bytes they used."""
    frames: list[Frame] = []
    used = 0
    while used < len(data):
        size, unit, tid, pdu = _tcp_framer.decode(data[used:])
        if not size:
            break
        frames.append(Frame(unit, tid, _decoder.decode(pdu), data[used:used + size]))
        used += size
    return frames, used


_tcp_framer = FramerSocket(_decoder)


def sort_rtu(frame: Frame, expected: Expected) -> tuple[UnitKind, object]:
    """An RTU frame as the reply machine sees it, with the echo token of a diagnostics answer
    (None for the exception reply of a unit that has no diagnostics)."""
    if frame.unit != expected.unit:
        return UnitKind.FOREIGN, None
    if frame.pdu is None:
        return UnitKind.GARBLED, None
    function = frame.pdu.function_code & 0x7F
    if function == expected.function:
        return UnitKind.ANSWER, None
    if function == DIAGNOSTICS:
        return UnitKind.SYNC, _echo_token(frame.pdu)
    return UnitKind.FOREIGN, None


def sort_tcp(frame: Frame, expected: Expected) -> tuple[UnitKind, object]:
    """A TCP frame as the reply machine sees it: by its transaction id, which only the answer
    to the request just sent carries; with that id, anything but the request's function (or
    an undecodable PDU) is that answer garbled."""
    if frame.tid != expected.tid or frame.unit != expected.unit:
        return UnitKind.FOREIGN, None
    if frame.pdu is None or frame.pdu.function_code & 0x7F != expected.function:
        return UnitKind.GARBLED, None
    return UnitKind.ANSWER, None


def _echo_token(pdu: ModbusPDU) -> object:
    if isinstance(pdu, ExceptionResponse):
        return None
    return pdu.message
