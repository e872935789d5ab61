"""Bring a Modbus RTU line back in step after a reply timeout, so a late reply is never read as
the answer to a later request.

RTU frames carry no transaction id: a reply that missed its timeout arrives later and, if it
has the shape the next request expects (the same unit, function and register count: the
detector's next reading), would be taken for that request's answer. After a timeout the
link therefore sends a diagnostics echo (function 08, sub-function 0000 "return query data")
with a fresh token and discards every byte up to its answer: the echoed frame (with at most
one byte lost or altered), or the unit's exception reply to function 08 (a unit that does
not implement diagnostics). A unit answers in order, so whatever was late has arrived by
then. The answer to an echo that
itself came too late is a function-08 frame, which the link rejects as a reply to anything
else (drivers.modbus_transport checks every reply's function code).
"""

from __future__ import annotations

import itertools
import os
import time

from pymodbus.framer.rtu import FramerRTU

from drivers.base import DeviceTimeout

DIAGNOSTICS = 0x08
RETURN_QUERY_DATA = b"\x00\x00"


def silent_interval_s(baudrate: int) -> float:
    """RTU's t3.5 at a baud rate: 3.5 characters of 11 bits, fixed 1.75 ms above 19200 baud
    (Modbus over Serial Line V1.02, 2.5.1.1). Bytes after this much silence are a new frame."""
    return 0.00175 if baudrate > 19200 else 3.5 * 11 / baudrate


def rtu_frame(unit: int, pdu: bytes) -> bytes:
    """An RTU frame: unit id, PDU, CRC-16 (Modbus byte order)."""
    body = bytes([unit]) + pdu
    return body + FramerRTU.compute_CRC(body).to_bytes(2, "big")


def _answered(data: bytes, echo: bytes, unit: int) -> bool:
    """True if data holds the answer to `echo`: the echo itself, or with one byte lost or
    altered (a garbled answer still shows that everything sent before it has come), or the
    unit's exception reply to function 08."""
    head = bytes([unit, DIAGNOSTICS | 0x80])
    start = data.find(head)
    while start >= 0:  # an exception reply, CRC checked (those two bytes occur in data too)
        if data[start:start + 5] == rtu_frame(unit, data[start + 1:start + 3]):
            return True
        start = data.find(head, start + 1)
    if any(echo[:i] + echo[i + 1:] in data for i in range(len(echo))):
        return True  # the echo, or the echo with one byte lost
    n = len(echo)
    return any(sum(a != b for a, b in zip(data[i:i + n], echo, strict=True)) <= 1
               for i in range(len(data) - n + 1))


class RtuSync:
    """The echo exchange of one RTU line (one per link; the caller holds the link's lock)."""

    def __init__(self) -> None:
        self._tokens = itertools.count(int.from_bytes(os.urandom(2), "big"))

    def resync(self, port, unit: int, device: str, what: str, reply_s: float) -> None:
        """Send an echo to `unit` on `port` (a pyserial port) and read up to its answer;
        DeviceTimeout naming `what` if it does not come within reply_s."""
        token = (next(self._tokens) % 0x10000).to_bytes(2, "big")
        echo = rtu_frame(unit, bytes([DIAGNOSTICS]) + RETURN_QUERY_DATA + token)
        # drop stale bytes and send; read / write raise OSError on a lost port (pyserial's
        # reset_input_buffer and flush would raise termios.error, which nothing maps)
        port.read(port.in_waiting)
        port.write(echo)
        deadline = time.monotonic() + reply_s
        received = bytearray()
        saved = port.timeout
        try:
            while not _answered(bytes(received), echo, unit):
                left = deadline - time.monotonic()
                if left <= 0:
                    raise DeviceTimeout(device, f"{what} (replies out of step after a timeout:"
                                        " no answer to the Modbus echo, function 08)", reply_s)
                port.timeout = left
                received += port.read(max(1, port.in_waiting))
            port.timeout = silent_interval_s(port.baudrate)  # the rest of a matched answer:
            while port.read(max(1, port.in_waiting)) and time.monotonic() < deadline:
                pass  # up to the silence ending its frame (a babbling line: the deadline)
        finally:
            port.timeout = saved
