"""Driver for Zaber X-series rotary stages over Zaber's ASCII protocol (serial, daisy chain).

From Zaber's ASCII protocol manual (firmware 7). Every request is `/<device> <axis> <id>
<command>:<CC>`: the message id (0..98 in turn; 99 is the sync query's) ties a reply to its
request, and CC is the manual's checksum (two hex digits: the two's complement of the byte
sum of what lies between '/' and ':'). Opening a device switches its reply checksums on
(comm.checksum 1, verified by read-back and left so); replies are then `@dd a id OK|RJ
BUSY|IDLE flag data:CC`, and one whose checksum, shape, address, axis or id is wrong is
garbled: a dropped digit of a position breaks the checksum rather than pass as another number.
RJ is a DeviceError naming the rejection reason. Queries are retried after a timeout or
garble; a state-changing command is sent exactly once, and if its reply is lost the driver
reads the device state back instead. After a timeout the sync query (`/<device> 0 99`) brings
late replies back in step (drivers.serial_transport).

A daisy chain is one serial port (or resource) on which each device answers to its address
(1..99). Controllers of devices on one port, in one process, share one transport
(`CHAIN_LINES`, drivers.shared_links): one hold of the port, one connection, one sync query
(the first controller's, to its device), each controller reading only the replies of its own
devices; the line opens with the first and closes with the last, and a controller asking for
other line settings than the open line's is refused (ValueError naming both).

Alerts (`!dd a IDLE flag[:CC]`: a device whose comm.alert is 1 telling that a motion ended,
sent when it happens) are left on or off as the lab saved them. A message's first character
is its type (Zaber's ASCII protocol article): `@` a reply, `#` an info message (sent after the
reply to some commands), `!` an alert (sent spontaneously when an event occurs). So the
transport sets every line starting with `!` aside (`is_alert`), wherever it arrives (begun
before a request and ended after it too) and its checksum right or wrong, and an alert costs
no retry and no resync.

Units: positions are microsteps, degrees = data x full_step_deg / resolution (the resolution,
microsteps per full step, read from each axis; full_step_deg defaults to the X-RSW60A's 0.015
deg, so 0.000234375 deg per microstep at the default resolution 64); maxspeed data = 1.6384 x
microsteps/s, accel data = 1.6384e-4 x microsteps/s^2.
"""

from __future__ import annotations

import itertools
import math
import re
from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Unpack

from drivers.base import DeviceError, DriverError, ProtocolError
from drivers.byte_link import LinkOptions
from drivers.lost_reply import LOST, not_resent, sent_once
from drivers.polling import poll_until
from drivers.port_identity import port_key
from drivers.serial_transport import SerialLineTransport, SyncQuery, line_settings
from drivers.settings import Setting, exactly
from drivers.shared_links import SharedLinks

X_RSW60A_STEP_DEG = 0.015  # stage rotation per full motor step
SPEED_UNIT = 1.6384  # maxspeed data per microstep/s
ACCEL_UNIT = 1.6384e-4  # accel data per microstep/s^2
SYNC_ID = 99  # the message id only the sync query uses

_REPLY = re.compile(r"@(\d{2}) (\d) (\d{2}) (OK|RJ) (BUSY|IDLE) (--|[A-Z]{2}) (\S+(?: \S+)*)")
_INTEGER = re.compile(r"-?\d+")
_HEX2 = re.compile(r"[0-9A-F]{2}")

# Rejection reasons (the data of an RJ reply), as the manual lists them.
REJECTIONS = {
    "AGAIN": "the command cannot be processed now; send it again",
    "BADAXIS": "no such axis on this device",
    "BADCOMMAND": "no such command or setting, or a read-only setting",
    "BADDATA": "data invalid or out of range (e.g. a target beyond limit.min/limit.max)",
    "BADMESSAGEID": "message id not -- or 0..99",
    "DEVICEONLY": "a device-only command or setting given an axis number",
    "FULL": "the device's storage is full",
    "LOCKSTEP": "the axis belongs to a lockstep group",
    "NOACCESS": "not available at the current access level",
    "PARKED": "the device is parked",
    "STATUSBUSY": "not possible while the device is busy",
}
# Warning flags (faults F*, warnings W*, notices N*); a reply shows the highest-priority one.
FLAGS = {
    "FD": "driver disabled itself (overheating)",
    "FQ": "encoder error: the measured position may be unreliable",
    "FS": "stalled and stopped itself",
    "FT": "lockstep group twisted too far and stopped",
    "FE": "limit sensor cannot be reached or is faulty",
    "WL": "a limit sensor cut a move short",
    "WV": "supply voltage outside the recommended range",
    "WT": "controller temperature above the recommended limit",
    "WM": "forced out of position while stationary",
    "WR": "no reference position (not homed)",
    "NC": "under manual control (knob)",
    "NI": "a movement command interrupted another",
    "NU": "a setting update or reset is pending",
}


def integer_setting(name: str, doc: str) -> Setting:
    """A setting `name` with integer data: `get name` asks it, `set name N` sets it, and the
    read-back must be N exactly."""
    return Setting(f"get {name}", f"set {name} {{}}", "integer", str, exactly, doc)


CHECKSUM = integer_setting("comm.checksum", "comm.checksum: 1 = replies carry a checksum")
LIMIT_MIN = integer_setting("limit.min", "limit.min: the lower travel limit, microsteps")
LIMIT_MAX = integer_setting("limit.max", "limit.max: the upper travel limit, microsteps")


#: the lines of the chains open in this process, by the port or resource they hold
CHAIN_LINES: SharedLinks[SerialLineTransport] = SharedLinks(SerialLineTransport.close)


def chain_endpoint(port: str | None, resource: str | None) -> str | None:
    """What a chain's line is known by: the key its port is held by (drivers.port_identity:
    the device file a port or ASRL resource opens, else the resource's canonical name); None
    unless exactly one of the two is given (which the transport refuses)."""
    if (port is None) == (resource is None):
        return None
    return port_key(port if resource is None else resource)


def lrc(text: str) -> str:
    """The manual's message checksum of `text`, two upper-case hex digits."""
    return f"{-sum(text.encode('ascii')) & 0xFF:02X}"


def is_alert(line: str) -> bool:
    """An alert: a message a device sends unprompted (`!`), never a reply to a request."""
    return line.startswith("!")


def flag_text(flag: str) -> str:
    """What a warning flag means."""
    kind = {"F": "fault", "W": "warning", "N": "notice"}.get(flag[:1], "flag")
    return FLAGS.get(flag, f"{kind} {flag}")


def blocks_motion(flag: str) -> bool:
    """A fault, or no position reference: the angle the axis reports cannot be trusted."""
    return flag.startswith("F") or flag == "WR"


@dataclass(frozen=True)
class Reply:
    """One parsed reply: OK or RJ, BUSY or IDLE, the warning flag and the data."""

    flag: str
    status: str
    warning: str
    data: str

    @property
    def busy(self) -> bool:
        return self.status == "BUSY"


def parse_reply(text: str, address: int, axis: int, message_id: int, checksummed: bool) -> Reply:
    """The reply to request `message_id` of device `address`, axis `axis`, read strictly: a
    checksum must match (and be there if `checksummed`), every field must have its shape,
    and address, axis and id must be the request's; anything else is a ProtocolError."""
    body, colon, cc = text.rpartition(":")
    if not colon:
        body = text
    if (colon or checksummed) and (not colon or _HEX2.fullmatch(cc) is None
                                   or lrc(body[1:]) != cc):
        raise ProtocolError(f"reply {text!r} fails its checksum")
    match = _REPLY.fullmatch(body)
    if match is None:
        kind = {"!": "an alert", "#": "an info message"}.get(text[:1], "a garbled reply")
        raise ProtocolError(f"{kind} where a reply was due: {text!r}")
    dev, ax, mid, flag, status, warning, data = match.groups()
    if (int(dev), int(ax), int(mid)) != (address, axis, message_id):
        raise ProtocolError(f"reply {text!r} answers another request (expected device "
                            f"{address}, axis {axis}, id {message_id})")
    return Reply(flag, status, warning, data)


class ZaberController:
    """The Zaber devices on one serial port (or, by `resource`, a VISA resource: LinkOptions);
    `axis(n, name, address)` gives engine-facing Axis objects. Controllers on one port share
    its line (`CHAIN_LINES`), so each device of a chain may have its own.

    address: the device (1..99) axes belong to unless axis() names another one of the daisy
    chain; timeout_s bounds every reply; retries is how often a query is re-asked; poll_s is
    how often wait() asks; full_step_deg: the stage's rotation per full motor step.
    """

    def __init__(
        self,
        port: str | None = None,
        baudrate: int = 115200,
        timeout_s: float = 1.0,
        name: str = "zaber",
        retries: int = 2,
        poll_s: float = 0.01,
        address: int = 1,
        full_step_deg: float = X_RSW60A_STEP_DEG,
        **link: Unpack[LinkOptions],
    ):
        _check_address(name, address)
        if not (full_step_deg > 0 and math.isfinite(full_step_deg)):
            raise ValueError(f"{name}: full_step_deg must be > 0, got {full_step_deg!r}")
        self.name, self.address = name, address
        self.poll_s, self.full_step_deg = poll_s, float(full_step_deg)
        self._ids = itertools.cycle(range(SYNC_ID))
        self._checksummed: set[int] = set()  # devices whose replies must carry a checksum
        self._devices: dict[int, dict[str, str]] = {}  # opened devices: their identity
        self._axis_counts: dict[int, int] = {}
        self.latest: dict[tuple[int, int], Reply] = {}  # (device, axis): its latest reply
        line = asdict(line_settings(name, baudrate, link))
        resource = link.get("resource")
        self._line_lease = CHAIN_LINES.open(
            chain_endpoint(port, resource), {**line, "timeout_s": timeout_s, "retries": retries},
            name, lambda: SerialLineTransport(
                port, name=name, write_eol=b"\n", read_eol=b"\r\n",
                timeout_s=timeout_s, retries=retries,
                sync=SyncQuery(self._line(address, 0, SYNC_ID, ""), self._is_sync_reply),
                is_unsolicited=is_alert, resource=resource, **line))
        self.transport = self._line_lease.link
        try:
            self._open(address)
        except BaseException:  # an interrupted open too: the chain's line goes with it
            self.close()
            raise

    # -- lifecycle --------------------------------------------------------------
    def close(self) -> None:
        """Give the chain's line back (the last controller on it closes the port)."""
        self._line_lease.release()

    def __enter__(self) -> ZaberController:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _open(self, address: int) -> None:
        """Reply checksums on (verified; comm.alert is left as it is), then the device's
        identity."""
        who = f"{self.name} device {address}"
        self.write_setting(CHECKSUM, 1, address, 0, who)
        self._checksummed.add(address)
        self._axis_counts[address] = self.get(address, 0, "system.axiscount", who)
        self._devices[address] = {
            "device_id": self.query(address, 0, "get deviceid", who).data,
            "serial": self.query(address, 0, "get system.serial", who).data,
            "firmware": self.query(address, 0, "get version", who).data,
            "address": str(address),
        }

    # -- messages ---------------------------------------------------------------
    @staticmethod
    def _line(address: int, axis: int, message_id: int, command: str) -> str:
        body = f"{address} {axis} {message_id}" + (f" {command}" if command else "")
        return f"/{body}:{lrc(body)}"

    def _parse(self, text: str, address: int, axis: int, message_id: int) -> Reply:
        try:
            return parse_reply(text, address, axis, message_id, address in self._checksummed)
        except ProtocolError as exc:
            raise ProtocolError(f"{self.name}: {exc}") from None

    def _is_sync_reply(self, text: str) -> bool:
        try:
            self._parse(text, self.address, 0, SYNC_ID)
        except ProtocolError:
            return False
        return True

    @staticmethod
    def _rejected(who: str, command: str, reply: Reply) -> DeviceError:
        meaning = REJECTIONS.get(reply.data, "rejected")
        return DeviceError(who, reply.data, f"{meaning} ({command!r})")

    def query(self, address: int, axis: int, command: str, who: str,
              integer: bool = False) -> Reply:
        """Ask something that changes nothing (integer: its data must be an integer);
        retried on timeout or garble, an RJ raises DeviceError (not retried)."""
        message_id = next(self._ids)

        def checked(text: str) -> Reply:
            reply = self._parse(text, address, axis, message_id)
            self.latest[address, axis] = reply
            if reply.flag == "RJ":
                raise self._rejected(who, command, reply)
            if integer and _INTEGER.fullmatch(reply.data) is None:
                raise ProtocolError(f"{who}: {command}: not an integer: {reply.data!r}")
            return reply

        return self.transport.query(self._line(address, axis, message_id, command), checked,
                                    f"{command or 'status'} (device {address} axis {axis})",
                                    self.name)

    def command(self, address: int, axis: int, command: str, who: str,
                verify: Callable[[], bool] | None = None) -> Reply | None:
        """Send a state-changing command exactly once. If its reply is lost or garbled,
        `verify()` (if given) reads the device state back; None when that confirmed it."""
        message_id = next(self._ids)
        what = f"{command!r} (device {address} axis {axis})"
        line = self._line(address, axis, message_id, command)

        def send() -> Reply:
            return self._parse(self.transport.exchange(line, what, self.name),
                               address, axis, message_id)

        reply = sent_once(send, lambda: _confirmed(verify), not_resent(who, command))
        if reply is None:
            return None
        self.latest[address, axis] = reply
        if reply.flag == "RJ":
            raise self._rejected(who, command, reply)
        return reply

    def get(self, address: int, axis: int, setting: str, who: str) -> int:
        """An integer setting of one axis (or of the device, axis 0)."""
        return int(self.query(address, axis, f"get {setting}", who, integer=True).data)

    def read_setting(self, setting: Setting, address: int, axis: int, who: str) -> int:
        """A declared setting of one axis (or of the device, axis 0), from its `get`."""
        return self.get(address, axis, setting.query.removeprefix("get "), who)

    def write_setting(self, setting: Setting, value: int, address: int, axis: int,
                      who: str) -> None:
        """Send a setting's `set` once (a lost reply settled by its read-back check), then
        read it back: DriverError unless it holds."""
        def holds() -> bool:
            return setting.check(value, self.read_setting(setting, address, axis, who), None)

        self.command(address, axis, setting.command_for(value), who, holds)
        got = self.read_setting(setting, address, axis, who)
        if not setting.check(value, got, None):
            name = setting.query.removeprefix("get ")
            raise DriverError(f"{who}: {name} reads back {got} after set to {value}")

    # -- devices and axes ---------------------------------------------------------
    def identity(self, address: int | None = None) -> dict[str, str]:
        """A device's identity as it reported it when opened (deviceid, system.serial,
        version) and its address."""
        return dict(self._devices[self.address if address is None else address])

    def estop(self, address: int | None = None) -> None:
        """estop: every axis of a device stops at once, without deceleration."""
        address = self.address if address is None else address
        self.command(address, 0, "estop", f"{self.name} device {address}")

    def axis(self, number: int, name: str | None = None, address: int | None = None) -> ZaberAxis:
        """The Axis object for axis `number` of device `address` (opened on first use)."""
        address = self.address if address is None else address
        _check_address(self.name, address)
        if address not in self._devices:
            self._open(address)
        count = self._axis_counts[address]
        if not (isinstance(number, int) and 1 <= number <= count):
            raise ValueError(f"{self.name}: device {address} has axes 1..{count}, got {number!r}")
        default = f"{self.name}.{number}" if address == self.address else \
            f"{self.name}.{address}.{number}"
        return ZaberAxis(self, address, number, name or default)


def _confirmed(verify: Callable[[], bool] | None) -> bool:
    """verify(), False when there is none or its own read-back fails too."""
    try:
        return verify is not None and verify()
    except LOST:
        return False


def _check_address(name: str, address: int) -> None:
    if not (isinstance(address, int) and not isinstance(address, bool) and 1 <= address <= 99):
        raise ValueError(f"{name}: device address must be 1..99, got {address!r}")


class ZaberAxis:
    """One axis of a Zaber device as the engine's Axis (degrees). It refuses to move, and
    wait() refuses to report an arrival, while the axis shows a fault or has no reference
    position (WR); home() acknowledges a fault and re-references it."""

    maxspeed = integer_setting("maxspeed", "maxspeed: speed, 1.6384 x microsteps/s")
    accel = integer_setting("accel", "accel: acceleration, 1.6384e-4 x microsteps/s^2")

    def __init__(self, controller: ZaberController, address: int, number: int, name: str):
        self.controller, self.address, self.number, self.name = controller, address, number, name
        resolution = self._get("resolution")
        if resolution < 1:
            raise ProtocolError(f"{name}: resolution {resolution} is not a microstep count")
        self.microstep_deg = controller.full_step_deg / resolution

    # -- messages ---------------------------------------------------------------
    @property
    def warning(self) -> str:
        """The warning flag of the latest reply from this axis."""
        return self.controller.latest[self.address, self.number].warning

    def _query(self, command: str, integer: bool = False) -> Reply:
        return self.controller.query(self.address, self.number, command, self.name, integer)

    def _command(self, command: str, verify: Callable[[], bool] | None = None) -> Reply | None:
        return self.controller.command(self.address, self.number, command, self.name, verify)

    def _get(self, setting: str) -> int:
        return self.controller.get(self.address, self.number, setting, self.name)

    def read_setting(self, setting: Setting) -> int:
        """A declared setting of this axis."""
        return self.controller.read_setting(setting, self.address, self.number, self.name)

    def write_setting(self, setting: Setting, value: int) -> None:
        """Set a declared setting of this axis once, and read it back."""
        self.controller.write_setting(setting, value, self.address, self.number, self.name)

    def _data(self, deg: float, per: float = 1.0) -> int:
        """Degrees (or deg/s, deg/s^2 with the unit `per`) as the device's integer data."""
        value = float(deg)
        if not math.isfinite(value):
            raise ValueError(f"{self.name}: not a finite number: {deg!r}")
        return round(value / self.microstep_deg * per)

    def _idle(self) -> bool:
        """IDLE in the latest reply from this axis."""
        return not self.controller.latest[self.address, self.number].busy

    def _blocked(self, why: str) -> DeviceError:
        return DeviceError(self.name, self.warning, f"{flag_text(self.warning)}; {why}")

    def _started(self, was_idle: bool, arrived: Callable[[Reply], bool]) -> bool:
        """After a lost reply to a motion command: did the device take it? Busy when it was
        idle before, or at rest where the command leads."""
        reply = self._query("get pos", integer=True)
        return (was_idle and reply.busy) or (not reply.busy and arrived(reply))

    # -- Axis interface ---------------------------------------------------------
    def move_to(self, position_deg: float) -> None:
        """move abs: start an absolute move (returns at once)."""
        target = self._data(position_deg)
        if blocks_motion(self.warning):
            raise self._blocked("home() the axis before moving it")
        was_idle = self._idle()
        reply = self._command(f"move abs {target}", lambda: self._started(
            was_idle, lambda r: int(r.data) == target))
        if reply is not None and blocks_motion(reply.warning):
            self.stop()
            raise self._blocked("stopped; home() the axis before moving it")

    def position(self) -> float:
        """get pos: actual position, degrees."""
        return self._get("pos") * self.microstep_deg

    def is_moving(self) -> bool:
        """BUSY while a move, stop or home is under way."""
        return self._query("").busy

    def wait(self, timeout_s: float) -> float:
        """Poll status and position together (get pos) until IDLE; returns the position that
        reply gave. DeviceError if the axis ended with a fault or without reference;
        DeviceTimeout after timeout_s."""
        def idle_at() -> float | None:
            reply = self._query("get pos", integer=True)
            if reply.busy:
                return None
            if blocks_motion(reply.warning):
                raise self._blocked("the motion did not end where it was sent")
            return int(reply.data) * self.microstep_deg

        return poll_until(idle_at, timeout_s, self.controller.poll_s, self.name,
                          "the motion to end (IDLE)")

    def stop(self) -> None:
        """stop: decelerate to rest; safe at any time."""
        self._command("stop")

    def estop(self) -> None:
        """estop: stop at once, without deceleration."""
        self._command("estop")

    def home(self) -> None:
        """home: find the home sensor and take it as reference (after acknowledging a fault
        with `warnings clear`); wait() waits for it."""
        if self.warning.startswith("F"):
            self._command("warnings clear",
                          lambda: not self._query("warnings").warning.startswith("F"))
        was_idle = self._idle()
        self._command("home", lambda: self._started(was_idle, lambda r: r.warning != "WR"))

    def identity(self) -> dict[str, str]:
        """The identity of the device this axis belongs to."""
        return self.controller.identity(self.address)

    def line_counts(self) -> dict[str, int]:
        """What the chain's line has seen (drivers.base.LineCounts)."""
        return self.controller.transport.line_counts()

    # -- settings ---------------------------------------------------------------
    def configure(self, speed_deg_s: float, accel_deg_s2: float,
                  limits_deg: tuple[float, float]) -> None:
        """Set maxspeed, accel and limit.min / limit.max, each sent once and read back (the
        device keeps whole units: the values it runs with are speed_deg_s and so on)."""
        speed = self._data(speed_deg_s, SPEED_UNIT)
        accel = self._data(accel_deg_s2, ACCEL_UNIT)
        lo, hi = self._data(limits_deg[0]), self._data(limits_deg[1])
        if speed < 1 or accel < 1:
            raise ValueError(f"{self.name}: speed {speed_deg_s!r} deg/s and acceleration "
                             f"{accel_deg_s2!r} deg/s^2 must be at least one device unit")
        if not lo < hi:
            raise ValueError(f"{self.name}: limits must be (lo, hi) with lo < hi, "
                             f"got {limits_deg!r}")
        self.maxspeed = speed
        self.accel = accel
        # order the two limits so that limit.min < limit.max holds in between
        pair = [(LIMIT_MIN, lo), (LIMIT_MAX, hi)]
        for setting, value in pair if lo < self.read_setting(LIMIT_MAX) else reversed(pair):
            self.write_setting(setting, value)

    @property
    def speed_deg_s(self) -> float:
        """maxspeed, deg/s."""
        return self.maxspeed / SPEED_UNIT * self.microstep_deg

    @property
    def accel_deg_s2(self) -> float:
        """accel, deg/s^2."""
        return self.accel / ACCEL_UNIT * self.microstep_deg

    @property
    def limits_deg(self) -> tuple[float, float]:
        """(limit.min, limit.max), degrees."""
        return self.read_setting(LIMIT_MIN) * self.microstep_deg, \
            self.read_setting(LIMIT_MAX) * self.microstep_deg
