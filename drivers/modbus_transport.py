"""Modbus RTU / TCP client link with bounded, named timeouts and retry of reads only.

One `ModbusLink` per endpoint (serial port or host:port), shared by every unit on it:
`open_link` hands out the same link to drivers of several units on one RTU bus or one
TCP server (a port however it is written: drivers.port_identity), and closes it when the last
user is done (drivers.shared_links); a unit asking for another line than the link's is
refused. Reads may be retried after a
timeout or a garbled reply; writes never are (a write may already have acted). A late reply
never answers a later request: drivers.reply_sync decides which request each frame answers
(drivers.modbus_frames cuts and sorts the frames); on TCP the connection is also closed after a
failed exchange (replies carry transaction ids, and a new connection carries nothing late); on
RTU the line is brought back in step by a diagnostics echo first (drivers.modbus_rtu_sync).
pymodbus gives the client's port or socket, its connection handling and every codec; the
request and reply loop is this module's, so a timeout is a timeout (no frame by the deadline)
and never read out of an exception's text. An RTU link holds its serial port
(drivers.port_lock) from its making to its close: while pymodbus's serial client has it open,
by the flock that client takes (pyserial's exclusive=True), and before and between its
connections by the hold's own.
"""

from __future__ import annotations

import logging
import select
import threading
import time
from dataclasses import asdict, dataclass

from pymodbus.client import ModbusTcpClient
from pymodbus.exceptions import ConnectionException
from pymodbus.pdu import ExceptionResponse, ModbusPDU, ReadDeviceInformationRequest
from pymodbus.pdu.register_message import (
    ReadHoldingRegistersRequest,
    ReadInputRegistersRequest,
    WriteMultipleRegistersRequest,
)

from drivers.base import DeviceError, DeviceTimeout, DriverError, ProtocolError
from drivers.byte_link import LineSettings, on_the_line
from drivers.modbus_frames import Expected, cut_rtu, cut_tcp, sort_rtu, sort_tcp
from drivers.modbus_rtu_client import RtuClient
from drivers.modbus_rtu_sync import EchoTokens, echo_answer_end, silent_interval_s
from drivers.port_identity import device_path, port_key, tcp_url
from drivers.port_lock import hold
from drivers.reply_sync import Event, Garbled, Reply, ReplySync, State, UnitKind
from drivers.shared_links import Lease, SharedLinks

BASIC_DEVICE_ID = 1  # read device id code: the basic objects, as a stream
# the basic objects VendorName, ProductCode, MajorMinorRevision (Modbus Application Protocol
# V1.1b3, 6.21) by object id -> the identity keys they give
BASIC_OBJECTS = {0: "vendor", 1: "model", 2: "firmware"}
MAX_TID = 65000  # transaction ids run 1..MAX_TID, as pymodbus's own client counts them
MODBUS_EXCEPTIONS = {
    1: "illegal function",
    2: "illegal data address",
    3: "illegal data value",
    4: "server device failure",
    5: "acknowledge",
    6: "server device busy",
    8: "memory parity error",
    10: "gateway path unavailable",
    11: "gateway target device failed to respond",
}

#: An RTU line as the Modbus serial-line specification sets it by default: even parity, one
#: stop bit (this driver's baud rate, 115200, is the drives' usual fast one).
RTU_LINE = LineSettings(115200, parity="even")
PYMODBUS_PARITY = {"none": "N", "even": "E", "odd": "O", "mark": "M", "space": "S"}

# pymodbus logs each failed connect and retry as lines of its own (Python's last-resort
# handler prints them on stderr); this driver's errors say once what failed, so the library's
# records go nowhere unless the program that runs gonio configures logging itself
logging.getLogger("pymodbus").addHandler(logging.NullHandler())


@dataclass(frozen=True)
class ModbusTimeouts:
    """Named time bounds of a link, seconds: one reply, and the pause after a failed read
    before it is retried (lets a late reply drain instead of answering the retry)."""

    reply_s: float = 0.5
    retry_pause_s: float = 0.02

    def __post_init__(self) -> None:
        for name in ("reply_s", "retry_pause_s"):
            value = getattr(self, name)
            if not 0.0 <= value < 60.0 or (name == "reply_s" and value == 0.0):
                raise ValueError(f"ModbusTimeouts: {name} must be in (0, 60) s, got {value!r}")


class ModbusLink:
    """A pymodbus client's port or socket for one endpoint, serialised by a lock: requests
    out, frames in through the reply machine, failures mapped to DriverErrors."""

    def __init__(self, transport: str, port_or_host: str, *, tcp_port: int = 502,
                 line: LineSettings = RTU_LINE, timeouts: ModbusTimeouts | None = None,
                 read_retries: int = 2, device: str = "modbus"):
        self.timeouts = timeouts or ModbusTimeouts()
        if transport not in ("tcp", "rtu"):
            raise ValueError(f"Modbus transport must be 'tcp' or 'rtu', got {transport!r}")
        if not isinstance(read_retries, int) or read_retries < 0:
            raise ValueError(f"read_retries must be an integer >= 0, got {read_retries!r}")
        self.transport, self.read_retries = transport, read_retries
        reply_s = self.timeouts.reply_s
        if transport == "tcp":
            self.endpoint = f"{port_or_host}:{tcp_port}"
            self._client = ModbusTcpClient(port_or_host, port=tcp_port, timeout=reply_s,
                                           retries=0)
            self._cut, self._sort, self._recv = cut_tcp, sort_tcp, self._recv_tcp
            # a TCP server serves several clients, but one gonio at a time drives its units:
            # the endpoint is held by name, as a VISA resource that names no file is
            self._held = hold(tcp_url("modbus-tcp", port_or_host, tcp_port), device)
        else:
            self.endpoint = port_or_host
            self._held = hold(port_or_host, device)  # the port is opened at the first request
            line = on_the_line(line, device_path(port_or_host))
            try:
                self._client = RtuClient(port_or_host, baudrate=line.baudrate,
                                         parity=PYMODBUS_PARITY[line.parity],
                                         stopbits=line.stopbits, timeout=reply_s, retries=0)
            except BaseException:
                self._held.release()
                raise
            self._cut, self._sort, self._recv = cut_rtu, sort_rtu, self._recv_rtu
        self._lock = threading.Lock()
        self.replies = ReplySync()  # which request each frame answers
        self._tid = 0
        self._echoes = EchoTokens()

    @property
    def in_step(self) -> bool:
        """False (RTU) from a missed reply until an echo is answered."""
        return self.replies.state is State.IN_STEP

    def read(self, device: str, table: str, address: int, count: int, unit: int) -> list[int]:
        """Read count registers of table ("holding" | "input"); retried on timeout / garble."""
        kind = ReadHoldingRegistersRequest if table == "holding" else ReadInputRegistersRequest
        what = f"{table} registers {address}..{address + count - 1} of unit {unit}"
        attempt = 0
        while True:
            try:
                return self._read_once(device, what, kind(address=address, count=count,
                                                         dev_id=unit), count)
            except (DeviceTimeout, ProtocolError):
                if attempt == self.read_retries:
                    raise
                attempt += 1
                time.sleep(self.timeouts.retry_pause_s)

    def _read_once(self, device: str, what: str, request: ModbusPDU, count: int) -> list[int]:
        reply = self._call(device, what, request)
        if len(reply.registers) != count:
            raise ProtocolError(f"{device}: {what}: {len(reply.registers)} registers in the "
                                f"reply, expected {count}")
        return list(reply.registers)

    def write(self, device: str, address: int, values: list[int], unit: int) -> None:
        """Write holding registers (function 16), once: never re-sent on a failure."""
        what = f"reply to a write of holding registers {address}.. of unit {unit}"
        self._call(device, what, WriteMultipleRegistersRequest(address=address, registers=values,
                                                               dev_id=unit))

    def identification(self, device: str, unit: int) -> dict[int, bytes]:
        """Read Device Identification (function 43, MEI 14) of the basic objects, sent once
        (a unit that lacks it may stay silent): {object id: value}."""
        reply = self._call(device, f"reply to a device identification (43/14) of unit {unit}",
                           ReadDeviceInformationRequest(BASIC_DEVICE_ID, 0, dev_id=unit))
        return {oid: value for oid, value in reply.information.items()
                if isinstance(value, bytes)}

    def _call(self, device: str, what: str, request: ModbusPDU) -> ModbusPDU:
        """Send request (RTU: after an echo if out of step) and return the frame the machine
        takes for its answer; a Modbus exception reply is a DeviceError."""
        with self._lock:
            try:
                if not self._client.connected:
                    self._connect()
                if self.replies.state is State.OUT_OF_STEP:
                    self._resync(request.dev_id, device, what)
                reply = self._exchange(request, device, what)
            except (ConnectionException, OSError) as exc:  # refused, reset, hung up
                self._lose_connection()
                raise DriverError(f"{device}: connection to {self.endpoint} failed or lost "
                                  f"({exc})") from None
            except (DeviceTimeout, ProtocolError):
                if self.transport == "tcp":  # a late or partial reply must not answer the next
                    self._lose_connection()
                raise
            finally:
                if self.replies.awaiting:  # a wait cut short (a signal): the reply may come
                    self.replies.timeout()
                    if self.transport == "tcp":
                        self._lose_connection()
        if isinstance(reply, ExceptionResponse):
            exc_code = reply.exception_code
            raise DeviceError(device, f"Modbus exception {exc_code:02d}",
                              f"{MODBUS_EXCEPTIONS.get(exc_code, 'unknown exception')} ({what})")
        return reply

    def _connect(self) -> None:
        if self.transport == "rtu":  # pymodbus opens with pyserial's exclusive=True: its flock
            self._held.hand_over()
        if not self._client.connect():
            raise ConnectionException(f"cannot open {self.endpoint}")
        if self.transport == "tcp":  # waits are on select: no poll inside every send and recv
            self._client.socket.setblocking(False)
        else:
            self._held.exclusive()

    def _lose_connection(self) -> None:
        self._client.close()
        if self.transport == "rtu":  # pymodbus's flock went with its port: the hold's guards it
            self._held.take_back()
        self.replies.reset()  # nothing sent on the old connection can arrive on a new one

    def _exchange(self, request: ModbusPDU, device: str, what: str) -> ModbusPDU:
        if self.transport == "tcp":
            self._tid = self._tid % MAX_TID + 1
            request.transaction_id = self._tid
        expected = Expected(request.dev_id, request.function_code, request.transaction_id)
        frame = self._client.framer.buildFrame(request)
        self.replies.send_request()
        self._client.send(frame)
        event = self._await(device, what, expected)
        if type(event) is Garbled:
            raise ProtocolError(f"{device}: {what}: garbled or mismatched reply "
                                f"{event.unit.raw.hex(' ')}")
        return event.unit.pdu

    def _await(self, device: str, what: str, expected: Expected) -> Event:
        """Feed the frames that arrive to the machine until one is the reply or a garbled one
        (late replies and late echo answers are passed over): that event; DeviceTimeout, the
        machine told, when none comes in time."""
        deadline = time.monotonic() + self.timeouts.reply_s
        data = b""
        while chunk := self._recv(deadline):
            data += chunk
            frames, used = self._cut(data)
            data = data[used:]
            for frame in frames:
                kind, sync_id = self._sort(frame, expected)
                event = self.replies.receive(kind, frame, sync_id)
                if type(event) is Reply or type(event) is Garbled:  # in step: the wait is over
                    return event
        self.replies.timeout()
        raise DeviceTimeout(device, what, self.timeouts.reply_s)

    def _recv_tcp(self, deadline: float) -> bytes:
        """The bytes that arrive on the socket by the deadline (b"": none)."""
        sock = self._client.socket
        left = deadline - time.monotonic()
        if left <= 0 or not select.select([sock], [], [], left)[0]:
            return b""
        if chunk := sock.recv(4096):
            return chunk
        raise ConnectionException(f"{self.endpoint} closed the connection")

    def _recv_rtu(self, deadline: float) -> bytes:
        """The bytes waiting on the port, or the first to arrive by the deadline and those
        with them (b"": none); the client's deadline, set by its send, is the same one."""
        return self._client.recv(None)

    def _resync(self, unit: int, device: str, what: str) -> None:
        """RTU: send a fresh echo to `unit` and drop every byte up to its answer (DeviceTimeout
        naming `what`, still out of step, if it does not come within reply_s), then the rest of
        that answer's frame up to the line's silence."""
        token, echo = self._echoes.next_echo(unit)
        self.replies.send_sync(token)
        self._client.send(echo)
        deadline = time.monotonic() + self.timeouts.reply_s
        received = b""
        while (end := echo_answer_end(received, echo, unit)) is None:
            chunk = self._recv_rtu(deadline)
            if not chunk:
                self.replies.timeout()
                if self.replies.state is State.IN_STEP:
                    return
                raise DeviceTimeout(device, f"{what} (replies out of step after a timeout: no "
                                    "answer to the Modbus echo, function 08)",
                                    self.timeouts.reply_s)
            received += chunk
        self.replies.receive(UnitKind.SYNC, received[:end], token)
        port = self._client.socket
        port.timeout = silent_interval_s(port.baudrate)  # the rest of a matched answer:
        while port.read(max(1, port.in_waiting)) and time.monotonic() < deadline:
            pass  # up to the silence ending its frame (a babbling line: the deadline)

    def close(self) -> None:
        """Close the client connection and release the port's hold."""
        with self._lock:
            try:
                self._client.close()
            finally:
                self._held.release()


#: the links open in this process, by the port or TCP endpoint (drivers.port_identity.port_key)
#: they reach: the units on one RTU bus or one TCP server share one, on one line's settings
LINKS: SharedLinks[ModbusLink] = SharedLinks(ModbusLink.close)


def open_link(transport: str, port_or_host: str, *, tcp_port: int = 502,
              line: LineSettings = RTU_LINE, timeouts: ModbusTimeouts | None = None,
              read_retries: int = 2, device: str = "modbus") -> Lease[ModbusLink]:
    """`device`'s lease of the shared link to an endpoint (made on first use, its serial port
    held for `device`, named if another process holds it). Every unit on the link asks for
    the same line (RTU), timeouts and retries: ValueError naming both devices otherwise."""
    timeouts = timeouts or ModbusTimeouts()
    settings = {**asdict(timeouts), "read_retries": read_retries}
    if transport == "rtu":
        endpoint = port_key(port_or_host)
        settings |= asdict(line)
    else:
        endpoint = port_key(tcp_url("modbus-tcp", port_or_host, tcp_port))
    return LINKS.open(endpoint, settings, device, lambda: ModbusLink(
        transport, port_or_host, tcp_port=tcp_port, line=line, timeouts=timeouts,
        read_retries=read_retries, device=device))
