"""One Modbus unit addressed by the names of its register map, over a shared link: the base of
the stage, detector and environment-sensor drivers (the map checked for what the driver needs,
reads by name, settings written once and read back, commands, status bits, identity)."""

from __future__ import annotations

from pathlib import Path
from typing import ClassVar

from drivers.base import DeviceError, DeviceTimeout, Interlocked, ProtocolError
from drivers.byte_link import LineSettings
from drivers.lost_reply import reraise, sent_once
from drivers.modbus_transport import (
    BASIC_OBJECTS,
    RTU_LINE,
    ModbusTimeouts,
    open_link,
)
from drivers.register_map import Register, RegisterMap, decode_text

INTERLOCK_BIT = "interlock"  # optional [status_bits] entry: the unit's interlock input is open
INTERLOCK_TEXT = "interlock input open (the unit stopped and refuses to run)"


class MappedUnit:
    """One Modbus unit reached through a shared link and addressed by register names.

    Base of the stage, detector and environment-sensor drivers: owns the link reference,
    reads and writes named registers through the map, closes on `close()` or leaving a `with`
    block. A driver names what its map must hold (`needs`: registers, [commands] and
    [status_bits]; `check_map` for more) and its default `name` (`kind_name`); a map without
    it is a ValueError once the link is open, which is then released.
    """

    kind_name: ClassVar[str] = "modbus-unit"
    needs: ClassVar[tuple[tuple[str, ...], tuple[str, ...], tuple[str, ...]]] = ((), (), ())

    def __init__(self, transport: str, port_or_host: str, unit: int,
                 register_map: str | Path | RegisterMap, *, name: str | None = None,
                 tcp_port: int = 502, line: LineSettings = RTU_LINE,
                 timeouts: ModbusTimeouts | None = None, read_retries: int = 2):
        name = self.kind_name if name is None else name
        if isinstance(unit, bool) or not isinstance(unit, int) or not 0 <= unit <= 247:
            raise ValueError(f"{name}: Modbus unit id must be an integer in 0..247, got {unit!r}")
        self.name, self.unit = name, unit
        self.map = (register_map if isinstance(register_map, RegisterMap)
                    else RegisterMap.load(register_map))
        self._lease = open_link(transport, port_or_host, tcp_port=tcp_port, line=line,
                                timeouts=timeouts, read_retries=read_retries, device=name)
        self.link = self._lease.link
        self._read_plans: dict[tuple[str, ...], list] = {}
        try:
            self.check_map()
        except ValueError:
            self.close()
            raise

    def check_map(self) -> None:
        """ValueError unless the map has what the driver needs (`needs`), before any traffic."""
        self.map.require(*self.needs)

    def read_values(self, *names: str) -> dict[str, float]:
        """Engineering values of the named registers, one read per table they lie in."""
        plan = self._read_plans.get(names)
        if plan is None:
            plan = self._read_plans[names] = self._read_plan(names)
        out = {}
        for table, first, count, group in plan:
            words = self.link.read(self.name, table, first, count, self.unit)
            out.update({n: self.map.take(n, first, words) for n in group})
        return out

    def _read_plan(self, names: tuple[str, ...]) -> list[tuple[str, int, int, tuple[str, ...]]]:
        """(table, first address, count, names) of each read covering names (made once per
        tuple of names: a driver asks for the same few sets again and again)."""
        by_table: dict[str, list[str]] = {}
        for n in names:
            by_table.setdefault(self.map.register(n).table, []).append(n)
        return [(*self.map.block(tuple(group)), tuple(group)) for group in by_table.values()]

    def read_value(self, name: str) -> float:
        """Engineering value of one named register."""
        return self.read_values(name)[name]

    def write_value(self, name: str, value: float) -> None:
        """Write one named holding register (checked against the map first), never re-sent."""
        self.write_values({name: value})

    def write_values(self, values: dict[str, float]) -> None:
        """Write named holding registers, in order, each once; every value is checked against
        the map before anything is written (bad input stops before any write).

        The map declares each setting (address, type, scale, range: its format); the
        read-back rule is the written words: if the reply to a setting's write is lost or
        garbled, the register is read back, and holding exactly the words written means the
        write was taken (the command register reads back nothing of the kind: its writes
        are resolved by the caller).
        """
        writes = []
        for name, value in values.items():
            reg = self.map.register(name)
            if reg.table != "holding" or not reg.writable:
                raise ValueError(f"{self.name}: register {name!r} is not writable in "
                                 f"{self.map.source}")
            writes.append((name, reg, self.map.encode(name, value)))
        for name, reg, words in writes:
            self._write_once(name, reg, words)

    def _write_once(self, name: str, reg: Register, words: list[int]) -> None:
        """Write one register's words once; a lost reply is settled by reading them back
        (never for the command register)."""
        sent_once(lambda: self.link.write(self.name, reg.address, words, self.unit),
                  lambda: name != "command" and self.link.read(
                      self.name, "holding", reg.address, reg.count, self.unit) == words,
                  reraise)

    def read_tuple(self, names: tuple[str, ...]) -> tuple[float, ...]:
        """Engineering values of the named registers, in the order named."""
        values = self.read_values(*names)
        return tuple(values[name] for name in names)

    def identity(self) -> dict[str, str]:
        """The unit's identity as it reports it: Read Device Identification (43/14: vendor,
        model, firmware) where it offers it, then the map's [identity] string registers for
        the names that did not give; blank strings left out, {} when it reports neither."""
        try:
            objects = self.link.identification(self.name, self.unit)
        except (DeviceError, DeviceTimeout, ProtocolError):  # not offered
            objects = {}
        found = {key: decode_text(objects[oid]) for oid, key in BASIC_OBJECTS.items()
                 if oid in objects}
        for name, reg in self.map.identity.items():
            if not found.get(name):
                found[name] = decode_text(self.link.read(self.name, reg.table, reg.address,
                                                         reg.count, self.unit))
        return {key: value for key, value in found.items() if value}

    def command(self, command: str) -> None:
        """Write a named value of the map's [commands] to the command register."""
        self.write_value("command", self.map.commands[command])

    def bits(self, status: float) -> dict[str, bool]:
        """Status register value -> {bit name: set} by the map's [status_bits]."""
        word = int(status)
        return {bit: bool(word >> n & 1) for bit, n in self.map.status_bits.items()}

    def check_interlock(self, bits: dict[str, bool]) -> None:
        """Interlocked if the status `bits` show the map's optional `interlock` bit set."""
        if bits.get(INTERLOCK_BIT):
            raise Interlocked(self.name, INTERLOCK_BIT, INTERLOCK_TEXT)

    def release_interlock(self) -> str | None:
        """What holds the unit's interlock (its status bit set), or None (also for a map
        without an interlock bit)."""
        if INTERLOCK_BIT not in self.map.status_bits:
            return None
        held = self.bits(self.read_value("status"))[INTERLOCK_BIT]
        return f"{self.name}: {INTERLOCK_TEXT}" if held else None

    def close(self) -> None:
        """Release the link (the last unit on it closes the connection); idempotent."""
        self._lease.release()

    def __enter__(self):
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
