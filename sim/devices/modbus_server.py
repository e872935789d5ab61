"""Serve emulated Modbus units with a real pymodbus 3.16 server: TCP (on 127.0.0.1 unless told
otherwise) or RTU on a pty.

Several units (unit ids) share one endpoint, as on one RTU bus or one TCP gateway. The
pymodbus server does the framing; each request lands in the addressed unit's `read` /
`write` (a `ModbusUnit`). RTU: one raw pty (sim.devices.modbus_pty); clients open its slave
(`endpoint`), the server reads and writes its master on the server's event loop.
Faults (latency, dropped / corrupted bytes, bad CRC, stalls, disconnects) act on the
reply frames, per unit (the unit's own injector) or for the whole endpoint. On TCP the
payload is guarded by TCP's own checksums, so dropped and corrupted bytes hit the 7-byte
MBAP header only, and a bad CRC does not apply.
"""

from __future__ import annotations

import asyncio
import itertools
import threading
import time
from collections import deque
from collections.abc import Mapping
from functools import partial
from typing import Protocol

from pymodbus.constants import ExcCodes
from pymodbus.datastore import ModbusServerContext
from pymodbus.exceptions import NoSuchIdException
from pymodbus.pdu import DecodePDU, ExceptionResponse, ModbusPDU
from pymodbus.pdu.diag_message import ReturnQueryDataRequest
from pymodbus.pdu.mei_message import ReadDeviceInformationRequest, ReadDeviceInformationResponse
from pymodbus.pdu.register_message import (
    ReadHoldingRegistersRequest,
    ReadInputRegistersRequest,
    ReadWriteMultipleRegistersRequest,
    WriteMultipleRegistersRequest,
    WriteSingleRegisterRequest,
)
from pymodbus.server import ModbusSerialServer, ModbusTcpServer

from sim.devices.faults import FaultInjector, FaultSpec
from sim.devices.modbus_pty import PtyLine
from sim.devices.pty_server import LOOPBACK
from sim.devices.register_map import (
    ILLEGAL_ADDRESS,
    ILLEGAL_FUNCTION,
    ILLEGAL_VALUE,
    DeviceLayout,
    Field,
    RegisterFile,
    Rejected,
)

_TABLE_OF_FUNCTION = {3: "holding", 4: "input", 23: "holding"}
# The requests the units answer; any other function or sub-function gets exception 01.
_ANSWERED = (ReadHoldingRegistersRequest, ReadInputRegistersRequest, WriteSingleRegisterRequest,
             WriteMultipleRegistersRequest, ReadWriteMultipleRegistersRequest,
             ReturnQueryDataRequest, ReadDeviceInformationRequest)
_ANSWERED_FUNCTIONS = frozenset(request.function_code for request in _ANSWERED)
RTU_CHARACTER_BITS = 11  # start, 8 data, parity (or a second stop bit), stop
RTU_FIXED_T35_S = 0.00175  # the spec's t3.5 above 19200 baud
_MBAP_BYTES = 7  # Modbus TCP header: transaction id, protocol id, length, unit id
FIRMWARE = "1.0.0-emulated"
BASIC_CONFORMITY = 0x81  # basic identification objects, stream and individual access
_SPECIFIC_OBJECT = 4  # read device id code: one object
_serials = itertools.count(1)


class ModbusUnit(Protocol):  # the server's view; EmulatedUnit is the usual implementation
    """What the server needs of an emulated unit."""

    faults: FaultInjector | None

    def read(self, table: str, address: int, count: int) -> list[int]:
        """Words of a register range (Rejected -> Modbus exception reply)."""

    def write(self, address: int, values: list[int]) -> None:
        """Store holding registers and act on them (Rejected -> exception reply)."""

    def identification(self) -> dict[int, bytes] | None:
        """Basic device identification objects (43/14) by id; None = function 43 not offered."""


class EmulatedUnit:
    """A unit whose registers follow a map: live registers are refreshed before a read,
    single-register settings are range-checked on write, and writes are then acted on.

    Its identity: vendor and model (the map's `vendor` and `name`), `serial` (one per unit
    unless given) and FIRMWARE, in the map's [identity] registers and, unless
    device_identification is False, answered to function 43 / MEI 14 too.
    Subclasses give `refresh(fields)` (update what a read is about to return) and
    `act(fields)` (do what the written registers ask).
    """

    def __init__(self, layout: DeviceLayout, faults: FaultSpec | None = None, *,
                 serial: str | None = None, device_identification: bool = True):
        self.layout = layout
        self.registers = RegisterFile(layout)
        self.faults = FaultInjector(faults) if faults is not None else None
        self.identity = {"vendor": layout.vendor, "model": layout.model,
                         "serial": serial or f"EMU{next(_serials):05d}", "firmware": FIRMWARE}
        for name in layout.identity:
            self.registers.set_text(name, self.identity.get(name, ""))
        self.device_identification = device_identification

    def identification(self) -> dict[int, bytes] | None:
        """VendorName, ProductCode (the model), MajorMinorRevision, if 43/14 is offered."""
        if not self.device_identification:
            return None
        return {oid: self.identity[key].encode("ascii", "replace")
                for oid, key in enumerate(("vendor", "model", "firmware"))}

    def read(self, table: str, address: int, count: int) -> list[int]:
        """Words of a register range, live values refreshed first."""
        self.refresh(self.registers.fields_in(table, address, count))
        return self.registers.read(table, address, count)

    def write(self, address: int, values: list[int]) -> None:
        """Check, store and act on a write of holding registers."""
        touched = self.registers.fields_in("holding", address, len(values))
        for f in touched:
            if f.width == 1 and f.writable:
                self.check(f, self.layout.from_words(f.name, [values[f.address - address]]))
        self.act(self.registers.write(address, values))

    def check(self, field: Field, value: float) -> None:
        """Refuse (exception 03) a single-register setting outside the map's range, or an
        unknown command."""
        if field.name == "command":
            if value not in self.layout.commands.values():
                raise Rejected(ILLEGAL_VALUE, f"unknown command {value:g}")
        elif not field.low <= value <= field.high:
            raise Rejected(ILLEGAL_VALUE, f"{field.name} = {value:g} outside the map's range")

    def refresh(self, fields: list[Field]) -> None:
        """Update the live registers among fields before they are read."""

    def act(self, fields: list[Field]) -> None:
        """React to the written fields."""

    def take_command(self) -> str | None:
        """The name of the command just written (the register then reads 0 again)."""
        value = self.registers.get("command")
        self.registers.set("command", 0)
        return next((n for n, v in self.layout.commands.items() if v == value), None)


class _UnitsContext(ModbusServerContext):
    """pymodbus datastore that hands each request to the addressed unit."""

    def __init__(self, units: Mapping[int, ModbusUnit]):
        # The base class only keeps devices for its own datastores; ours are the units, all
        # called from the server's one event-loop thread.
        self.old_simulator = True
        self.simdevices = []
        self._units = dict(units)
        self._echo: dict[int, list[int]] = {}

    def unit(self, device_id: int) -> ModbusUnit:
        """The unit with this id (NoSuchIdException: pymodbus then answers as for any
        absent unit)."""
        unit = self._units.get(device_id)
        if unit is None:
            raise NoSuchIdException(f"no unit {device_id}")
        return unit

    async def async_getValues(self, device_id, func_code, address, count=1):  # noqa: N802
        unit = self.unit(device_id)
        if func_code == 6:  # a write-single echo: the word just written
            return self._echo.get(device_id, [0])[:1]
        try:
            return unit.read(_TABLE_OF_FUNCTION[func_code], address, count)
        except Rejected as exc:
            return ExcCodes(exc.code)

    async def async_setValues(self, device_id, func_code, address, values):  # noqa: N802
        unit = self.unit(device_id)
        try:
            unit.write(address, list(values))
        except Rejected as exc:
            return ExcCodes(exc.code)
        self._echo[device_id] = list(values)
        return None

    def device_ids(self):
        return list(self._units)


class _Refused(ModbusPDU):
    """A request the units do not answer as asked: an exception reply with its own function
    code (01 for a function or sub-function they lack, 03 for one of theirs too short to
    decode). An absent unit stays absent (11 on TCP, silence on RTU)."""

    def __init__(self, function_code: int, exception_code: int):
        super().__init__()
        self.function_code, self.exception_code = function_code, exception_code

    async def datastore_update(self, context: _UnitsContext, device_id: int) -> ModbusPDU:
        """Exception reply of the addressed unit."""
        context.unit(device_id)
        return ExceptionResponse(self.function_code, ExcCodes(self.exception_code))


class _UnitsDecoder(DecodePDU):
    """pymodbus's request decoder limited to what the units answer (`_ANSWERED`).

    pymodbus would answer a function it does not know with function byte 0x80, and its
    process-wide diagnostics (function 08 other than the echo, 07, 11, 12, 17, ...) with its
    own defaults or, for a reserved sub-function such as 08/0008, exception 04. Here each of
    those is the unit's exception 01 (illegal function), as the Modbus application protocol
    (V1.1b3, 6.8 and 7) asks of an unsupported function or sub-function.
    Function 43/14 is answered per unit (`_identification`)."""

    def lookupPduClass(self, data: bytes) -> type[ModbusPDU] | None:  # noqa: N802
        """The RTU framer's length rule: a sub-function pymodbus lacks (08/0008) is framed
        by its function's rule, so that it is answered instead of hunted past in silence."""
        found = super().lookupPduClass(data)
        return found or self.pdu_table.get(data[1], (None, None))[self.pdu_inx]

    def decode(self, frame: bytes) -> ModbusPDU:
        """The request in a frame's PDU, or a `_Refused` one."""
        if frame[0] not in _ANSWERED_FUNCTIONS:
            return _Refused(frame[0], ILLEGAL_FUNCTION)
        request = super().decode(frame)
        if request is None:
            return _Refused(frame[0], ILLEGAL_VALUE)
        if type(request) not in _ANSWERED:
            return _Refused(frame[0], ILLEGAL_FUNCTION)
        if isinstance(request, ReadDeviceInformationRequest):
            request.datastore_update = partial(_identification, request)
        return request


class _Connection:
    """One client connection (or the RTU line), answered as a device does: every request in
    the bytes received, one after another in arrival order. On TCP each reply is sent (after
    any injected latency) before the connection's next request is handled; an RTU master
    sends one request at a time, and there each reply keeps its own delay, so a late reply
    can overlap the next exchange, as on a line.

    pymodbus 3.16 takes one request per receive, clears its receive buffer whenever it
    sends, and empties it when it holds more than 264 bytes: of three requests in one TCP
    segment only the first was answered, of 100 none. Here the connection keeps its own
    buffer and takes every complete frame from it. pymodbus's request handler
    (`handle_request`) answers the request in `last_pdu`; the units answer without
    suspending, so each request is answered whole before the next is put there.
    On RTU a silence of t3.5 (`gap_s`) ends a frame: leftovers of a truncated or garbled
    frame are dropped before the bytes after the silence are parsed. (A complete frame needs
    no silence: pymodbus's framer takes it as soon as its function code's length has arrived
    and its CRC checks, so the interval never delays a reply.)
    """

    def __init__(self, handler, emulator: ModbusEmulatorServer):
        self.handler = handler
        self.in_order = emulator.transport == "tcp"
        self.gap_s = None if self.in_order else rtu_silent_interval_s(emulator.baudrate)
        self.received = b""
        self.last_byte_s = 0.0
        self.requests: deque[ModbusPDU] = deque()
        self.reply_sent: asyncio.Future | None = None
        self._answering: asyncio.Task | None = None
        handler.trace_packet = lambda sending, data: (
            emulator.outgoing(self, data) if sending else data)
        handler.trace_pdu = lambda sending, pdu: pdu if sending else self._queue(pdu)
        handler.handle_later = self._answer_soon
        handler.data_received = self.data_received

    def data_received(self, data: bytes) -> None:
        """Take every complete request frame from the bytes received so far."""
        now = time.monotonic()
        if self.gap_s is not None and now - self.last_byte_s > self.gap_s:
            self.received = b""
        self.last_byte_s = now
        self.received += data
        while self.received:
            used = self.handler.callback_data(self.received)
            if not used:
                break
            self.received = self.received[used:]
        if len(self.received) > self.handler.max_buffer_size:  # no frame can start here
            self.received = b""

    def _queue(self, request: ModbusPDU) -> ModbusPDU:
        self.requests.append(request)
        return request

    def _answer_soon(self) -> None:
        if self._answering is None or self._answering.done():
            self._answering = self.handler.loop.create_task(self._answer_all())

    async def _answer_all(self) -> None:
        while self.requests and self.handler.transport is not None:
            self.handler.last_pdu = self.requests.popleft()
            await self.handler.handle_request()
            if self.reply_sent is not None:
                await self.reply_sent
                self.reply_sent = None


class _FaultyReplies:
    """Mixin for the pymodbus servers: each connection a `_Connection`."""

    emulator: ModbusEmulatorServer

    def callback_new_connection(self):
        handler = super().callback_new_connection()
        _Connection(handler, self.emulator)
        return handler


async def _identification(request: ReadDeviceInformationRequest, context: _UnitsContext,
                          device_id: int):
    """A unit's basic identification objects: from object_id on for a stream read (codes 1..3;
    a unit of basic conformity answers 2 and 3 with its basic objects, and an unknown start
    with all of them), or the one asked (code 4; exception 02 if it has none such).
    Exception 01 from a unit that does not offer function 43."""
    objects = context.unit(device_id).identification()
    code = request.function_code
    if objects is None:
        return ExceptionResponse(code, ExcCodes(ILLEGAL_FUNCTION))
    if not 1 <= request.read_code <= _SPECIFIC_OBJECT:
        return ExceptionResponse(code, ExcCodes(ILLEGAL_VALUE))
    if request.read_code == _SPECIFIC_OBJECT:
        if request.object_id not in objects:
            return ExceptionResponse(code, ExcCodes(ILLEGAL_ADDRESS))
        chosen = {request.object_id: objects[request.object_id]}
    else:
        first = request.object_id if request.object_id in objects else 0
        chosen = {oid: value for oid, value in objects.items() if oid >= first}
    reply = ReadDeviceInformationResponse(read_code=request.read_code, information=chosen,
                                          dev_id=device_id)
    reply.conformity = BASIC_CONFORMITY
    return reply


def rtu_silent_interval_s(baudrate: int) -> float:
    """RTU's t3.5, the silence that ends a frame: 3.5 characters of 11 bits at the baud rate,
    and a fixed 1.75 ms above 19200 baud (Modbus over Serial Line V1.02, 2.5.1.1)."""
    if baudrate > 19200:
        return RTU_FIXED_T35_S
    return 3.5 * RTU_CHARACTER_BITS / baudrate


class _TcpServer(_FaultyReplies, ModbusTcpServer):
    pass


class _SerialServer(_FaultyReplies, ModbusSerialServer):
    pass


class ModbusEmulatorServer:
    """One Modbus endpoint (TCP server or RTU on a pty) serving several units.

    faults: a FaultSpec for replies of units without their own injector; host: the address
    a TCP server listens on (loopback unless the caller opens it to the network). start()
    returns the endpoint ("HOST:PORT", or the pty path for RTU); stop() ends it.
    """

    def __init__(self, transport: str = "tcp", units: Mapping[int, ModbusUnit] | None = None,
                 faults: FaultSpec | None = None, *, port: int = 0, baudrate: int = 115200,
                 host: str = LOOPBACK):
        if transport not in ("tcp", "rtu"):
            raise ValueError(f"Modbus transport must be 'tcp' or 'rtu', got {transport!r}")
        if not units:
            raise ValueError("ModbusEmulatorServer needs at least one unit")
        if isinstance(baudrate, bool) or not isinstance(baudrate, int) or baudrate <= 0:
            raise ValueError(f"Modbus RTU baud rate must be a positive integer, got {baudrate!r}")
        for unit_id in units:
            if isinstance(unit_id, bool) or not isinstance(unit_id, int) or not 1 <= unit_id <= 247:
                raise ValueError(f"Modbus unit ids are integers 1..247, got {unit_id!r}")
        self.transport = transport
        self.units = dict(units)
        self.faults = FaultInjector(faults)
        self.host, self.port, self.baudrate = host, port, baudrate
        self.endpoint: str | None = None
        self.disconnected = False
        self.late_replies = 0  # replies held back (latency, a hang-up): a test's count
        self.late_pending = 0  # of those, how many are not out yet
        self._loop: asyncio.AbstractEventLoop | None = None
        self._server = None
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._line: PtyLine | None = None

    @property
    def protocol(self) -> str:
        """"modbus-tcp" or "modbus-rtu"."""
        return f"modbus-{self.transport}"

    # -- lifecycle ----------------------------------------------------------------
    def start(self) -> str:
        """Start serving in a background thread; returns the endpoint."""
        if self._thread is not None:
            raise RuntimeError("ModbusEmulatorServer already started")
        if self.transport == "rtu":
            self._line = PtyLine()
            self.endpoint = self._line.path
        self._thread = threading.Thread(target=self._run, name=f"{self.protocol}-server",
                                        daemon=True)
        self._thread.start()
        if not self._ready.wait(10.0) or self._error is not None:
            self.stop()
            raise RuntimeError(f"{self.protocol} emulator failed to start: {self._error!r}")
        return self.endpoint

    def stop(self) -> None:
        """Stop the server and close its sockets / ptys (idempotent)."""
        loop = self._loop
        if loop is not None and loop.is_running():
            if self._server is not None:
                fut = asyncio.run_coroutine_threadsafe(self._server.shutdown(), loop)
                try:
                    fut.result(5.0)
                except Exception:  # noqa: BLE001 - stopping anyway
                    pass
            loop.call_soon_threadsafe(loop.stop)
        if self._thread is not None:
            self._thread.join(5.0)
        if self._line is not None:
            self._line.close()
        self._server = None

    def __enter__(self) -> ModbusEmulatorServer:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _run(self) -> None:
        loop = self._loop = asyncio.new_event_loop()
        asyncio.set_event_loop(loop)
        try:
            loop.run_until_complete(self._listen())
        except BaseException as exc:  # noqa: BLE001 - reported to start()
            self._error = exc
            self._ready.set()
            loop.close()
            return
        self._ready.set()
        loop.run_forever()
        loop.run_until_complete(asyncio.sleep(0))
        loop.close()

    async def _listen(self) -> None:
        context = _UnitsContext(self.units)
        if self.transport == "tcp":
            server = _TcpServer(context, address=(self.host, self.port))
        else:
            server = _SerialServer(context, port=self._line.path, baudrate=self.baudrate,
                                   ignore_missing_devices=True)
            server.call_create = partial(self._line.open, server.handle_new_connection)
        server.emulator = self
        server.decoder = _UnitsDecoder(True)
        await server.serve_forever(background=True)
        if self.transport == "tcp":
            if not server.transport:
                raise RuntimeError(f"cannot listen on {self.host}:{self.port}")
            port = server.transport.sockets[0].getsockname()[1]
            self.endpoint = f"{self.host}:{port}"
        self._server = server

    # -- faults --------------------------------------------------------------------
    def outgoing(self, connection: _Connection, frame: bytes) -> bytes:
        """Called by pymodbus with each reply frame: send it through the unit's faults.

        A delayed frame (injected latency) or the last before a hang-up goes out later from
        the event loop, so a slow unit does not block the server (on TCP the connection's next
        request waits for it); any other goes out now. pymodbus itself sends nothing.
        """
        unit_id = frame[0] if self.transport == "rtu" else frame[6] if len(frame) > 6 else 0
        unit = self.units.get(unit_id)
        if unit is None and self.transport == "rtu":
            return b""  # pymodbus answers garbled requests for any id; absent units are silent
        faults = unit.faults if unit is not None and unit.faults is not None else self.faults
        if self.transport == "rtu":
            out = faults.reply(frame, crc_bytes=2)
        else:  # TCP checksums guard the payload: dropped / corrupted bytes hit the MBAP header
            out = faults.reply(frame, keep_tail=max(len(frame) - _MBAP_BYTES, 0))
        hang_up, delay_s = faults.should_disconnect(), faults.delay()
        if delay_s or hang_up:
            if connection.in_order:
                connection.reply_sent = self._loop.create_future()
            self.late_replies += 1
            self.late_pending += 1
            self._loop.call_later(delay_s, self._deliver_late, connection, out, hang_up)
        else:
            self._deliver(connection, out, False)
        return b""

    def _deliver_late(self, connection: _Connection, data: bytes | None, hang_up: bool) -> None:
        self._deliver(connection, data, hang_up)
        self.late_pending -= 1

    def _deliver(self, connection: _Connection, data: bytes | None, hang_up: bool) -> None:
        if connection.reply_sent is not None and not connection.reply_sent.done():
            connection.reply_sent.set_result(None)
        handler = connection.handler
        transport = handler.transport
        if transport is None or self.disconnected:
            return
        if data:
            transport.write(data)
        if hang_up:
            if self.transport == "rtu":
                self.disconnected = True
                transport.hang_up()
            else:
                handler.close()
