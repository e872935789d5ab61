"""The sync query of a Modbus RTU line: a diagnostics echo, and how its answer is recognised.

RTU frames carry no transaction id: a reply that missed its timeout arrives later and, if it
has the shape the next request expects (the same unit, function and register count: the
detector's next reading), would be taken for that request's answer. After a timeout the
link (drivers.modbus_transport, with drivers.reply_sync deciding) therefore sends a
diagnostics echo (function 08, sub-function 0000 "return query data") with a fresh token and
discards every byte up to its answer: the echoed frame (with at most one byte lost or
altered: a garbled answer still shows that everything sent before it has come), or the
unit's exception reply to function 08 (a unit that does not implement diagnostics). A unit
answers in order, so whatever was late has arrived by then. The answer to an echo that itself
came too late is a function-08 frame, which the machine takes for a late sync reply.
"""

from __future__ import annotations

import itertools
import os

from pymodbus.framer import FramerRTU

from drivers.modbus_frames import DIAGNOSTICS

RETURN_QUERY_DATA = b"\x00\x00"
EXCEPTION_REPLY_BYTES = 5  # unit, function | 0x80, exception code, CRC


def silent_interval_s(baudrate: int) -> float:
    """RTU's t3.5 at a baud rate: 3.5 characters of 11 bits, fixed 1.75 ms above 19200 baud
    (Modbus over Serial Line V1.02, 2.5.1.1). Bytes after this much silence are a new frame."""
    return 0.00175 if baudrate > 19200 else 3.5 * 11 / baudrate


def rtu_frame(unit: int, pdu: bytes) -> bytes:
    """An RTU frame: unit id, PDU, CRC-16 (Modbus byte order)."""
    body = bytes([unit]) + pdu
    return body + FramerRTU.compute_CRC(body).to_bytes(2, "big")


class EchoTokens:
    """Fresh echo tokens for one line, starting at a random value (so a late echo answer from
    an earlier session is not taken for this one's)."""

    def __init__(self) -> None:
        self._tokens = itertools.count(int.from_bytes(os.urandom(2), "big"))

    def next_echo(self, unit: int) -> tuple[bytes, bytes]:
        """(token, the echo frame to send to unit)."""
        token = (next(self._tokens) % 0x10000).to_bytes(2, "big")
        return token, rtu_frame(unit, bytes([DIAGNOSTICS]) + RETURN_QUERY_DATA + token)


def echo_answer_end(data: bytes, echo: bytes, unit: int) -> int | None:
    """Where in data the answer to `echo` ends: the echo itself, or with one byte lost or
    altered, or the unit's exception reply to function 08; None while data holds none."""
    exact = data.find(echo)
    if exact >= 0:
        return exact + len(echo)
    head = bytes([unit, DIAGNOSTICS | 0x80])
    start = data.find(head)
    while start >= 0:  # an exception reply, CRC checked (those two bytes occur in data too)
        if data[start:start + EXCEPTION_REPLY_BYTES] == rtu_frame(unit, data[start + 1:start + 3]):
            return start + EXCEPTION_REPLY_BYTES
        start = data.find(head, start + 1)
    n = len(echo)
    for i in range(n):  # the echo with byte i lost
        found = data.find(echo[:i] + echo[i + 1:])
        if found >= 0:
            return found + n - 1
    for i in range(len(data) - n + 1):  # the echo with one byte altered
        if sum(a != b for a, b in zip(data[i:i + n], echo, strict=True)) <= 1:
            return i + n
    return None
