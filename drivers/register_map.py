"""Client-side reader of a Modbus register-map file (TOML): register layout and value codecs.

A map names each register (table, 0-based address, type, scale, access, range) and the
drive's command values, status bits and fault codes; `RegisterMap.encode` / `decode`
turn engineering values into 16-bit words and back in the map's word order. An optional
`[identity]` table names ASCII string registers (vendor, model, serial, firmware...), two
characters per register, first character in the high byte; `decode_text` reads them. An
optional `interlock` entry of [status_bits] names the bit of `status` a unit sets while its
interlock input is open (it stops and refuses to run until the input closes again).
"""

from __future__ import annotations

import math
import struct
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from drivers.user_file import SETTINGS_FILE_CAP, read_user_text

_TYPES = {  # type -> (struct code of its big-endian bytes, number of registers)
    "uint16": ("H", 1),
    "int16": ("h", 1),
    "uint32": ("I", 2),
    "int32": ("i", 2),
    "float32": ("f", 2),
}
_VALUE_CODECS = {kind: struct.Struct(">" + code) for kind, (code, _) in _TYPES.items()}
_WORD_CODECS = {n: struct.Struct(f">{n}H") for n in (1, 2)}  # big-endian 16-bit words
_TABLES = ("holding", "input")
_ACCESS = ("r", "rw")
_TEXT_KEYS = ("table", "address", "count", "description")
MAX_READ_REGISTERS = 125  # the most registers one Modbus read (03 / 04) may ask for
#: the registers an environment sensor's map names: deg C and relative humidity (a fraction)
ROOM_REGISTERS = ("temperature", "humidity")


class RegisterMapError(ValueError):
    """A register-map file that is missing a field or has a bad one (the message names it)."""


@dataclass(frozen=True)
class Register:
    """One named register (or register pair) of a map."""

    name: str
    table: str
    address: int
    type: str
    scale: float
    access: str
    unit: str
    min: float | None
    max: float | None

    @property
    def count(self) -> int:
        """Number of 16-bit registers the value spans."""
        return _TYPES[self.type][1]

    @property
    def writable(self) -> bool:
        """True when a host may write this register."""
        return self.access == "rw"


@dataclass(frozen=True)
class TextRegister:
    """An identity string of the map's [identity] table: `count` registers of ASCII."""

    name: str
    table: str
    address: int
    count: int


@dataclass(frozen=True)
class FaultCode:
    """A drive fault code and its text from the map."""

    name: str
    code: int
    text: str


class RegisterMap:
    """A parsed register map: registers by name, commands, status bits, fault codes."""

    def __init__(self, table: Mapping, source: str = "register map"):
        self.source = source
        self.name = _field(table, "name", str, source)
        self.word_order = _field(table, "word_order", str, source)
        if self.word_order not in ("big", "little"):
            raise RegisterMapError(
                f"{source}: word_order must be 'big' or 'little', got {self.word_order!r}"
            )
        regs = _field(table, "registers", dict, source)
        self.registers = {name: _register(name, spec, source) for name, spec in regs.items()}
        commands = _section(table, "commands", source)
        self.commands = {n: _int_field(commands, n, f"{source}: [commands]") for n in commands}
        bits = _section(table, "status_bits", source)
        self.status_bits = {n: _int_field(bits, n, f"{source}: [status_bits]") for n in bits}
        _check_interlock_bit(self.status_bits, source)
        self.fault_codes = {
            spec["code"]: FaultCode(name, spec["code"], spec["text"])
            for name, spec in _fault_table(_section(table, "fault_codes", source), source).items()
        }
        self.gain_ranges_w = _gain_ranges(_section(table, "gain_ranges", source), source)
        self.identity = {name: _text_register(name, spec, source)
                         for name, spec in _section(table, "identity", source).items()}
        self._check_overlap()

    @classmethod
    def load(cls, path: str | Path) -> RegisterMap:
        """Read and check a map file; RegisterMapError names the file and the field."""
        path = Path(path)
        text = read_user_text(path, "register map", SETTINGS_FILE_CAP, RegisterMapError)
        try:
            table = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise RegisterMapError(f"{path}: cannot read register map: {exc}") from None
        return cls(table, source=str(path))

    def register(self, name: str) -> Register:
        """The register called name (RegisterMapError if the map lacks it)."""
        try:
            return self.registers[name]
        except KeyError:
            raise RegisterMapError(f"{self.source}: no register {name!r}") from None

    def require(self, registers: tuple[str, ...], commands: tuple[str, ...] = (),
                bits: tuple[str, ...] = ()) -> None:
        """Check that the map has what a driver needs, before any traffic."""
        for name in registers:
            self.register(name)
        for group, names, have in (("commands", commands, self.commands),
                                   ("status_bits", bits, self.status_bits)):
            missing = [n for n in names if n not in have]
            if missing:
                raise RegisterMapError(f"{self.source}: [{group}] lacks {', '.join(missing)}")

    def encode(self, name: str, value: float) -> list[int]:
        """Engineering value -> register words (RegisterMapError if out of range or type)."""
        reg = self.register(name)
        low = -math.inf if reg.min is None else reg.min
        high = math.inf if reg.max is None else reg.max
        if not low <= value <= high:
            raise RegisterMapError(
                f"{self.source}: {name} = {value!r} outside [{reg.min}, {reg.max}] {reg.unit}"
            )
        code, _ = _TYPES[reg.type]
        scaled = float(value) * reg.scale  # a huge value times the scale may overflow to inf
        raw: float | int = scaled if reg.type == "float32" or not math.isfinite(scaled) \
            else round(scaled)
        try:
            data = struct.pack(">" + code, raw)
        except (struct.error, OverflowError, ValueError):
            raise RegisterMapError(
                f"{self.source}: {name} = {value!r} does not fit a {reg.type} register "
                f"(scale {reg.scale:g})"
            ) from None
        return self._order([int.from_bytes(data[i:i + 2], "big") for i in range(0, len(data), 2)])

    def decode(self, name: str, words: list[int]) -> float:
        """Register words -> engineering value."""
        reg = self.register(name)
        if len(words) != reg.count:
            raise RegisterMapError(f"{name} needs {reg.count} registers, got {len(words)}")
        (raw,) = _VALUE_CODECS[reg.type].unpack(_WORD_CODECS[reg.count].pack(
            *self._order(list(words))))
        return raw / reg.scale

    def block(self, names: tuple[str, ...]) -> tuple[str, int, int]:
        """(table, first address, count) of one read covering the named registers."""
        regs = [self.register(n) for n in names]
        tables = {r.table for r in regs}
        if len(tables) != 1:
            raise RegisterMapError(f"{self.source}: {names} are not in one table")
        first = min(r.address for r in regs)
        last = max(r.address + r.count for r in regs)
        return tables.pop(), first, last - first

    def take(self, name: str, first: int, words: list[int]) -> float:
        """Decode register name out of a block read that started at address first."""
        reg = self.register(name)
        offset = reg.address - first
        return self.decode(name, words[offset:offset + reg.count])

    def fault_text(self, code: int) -> str:
        """The map's text for a fault code (or 'unknown fault code')."""
        fault = self.fault_codes.get(code)
        return fault.text if fault else "unknown fault code"

    def _order(self, words: list[int]) -> list[int]:
        return words[::-1] if self.word_order == "little" else words

    def _check_overlap(self) -> None:
        used: dict[tuple[str, int], str] = {}
        spans = [*self.registers.items(),
                 *((f"identity.{name}", r) for name, r in self.identity.items())]
        for name, reg in spans:
            for addr in range(reg.address, reg.address + reg.count):
                other = used.setdefault((reg.table, addr), name)
                if other != name:
                    raise RegisterMapError(
                        f"{self.source}: registers {other!r} and {name!r} overlap at "
                        f"{reg.table} address {addr}"
                    )


def decode_text(data: bytes | list[int]) -> str:
    """ASCII bytes, or string registers (two characters each, high byte first), as text:
    NUL and space padding at either end dropped, a byte that is not printable ASCII shown
    as U+FFFD."""
    if isinstance(data, list):
        data = b"".join(w.to_bytes(2, "big") for w in data)
    raw = data.strip(b"\0 ")
    return "".join(chr(b) if 32 <= b < 127 else "\ufffd" for b in raw)


def _field(table: Mapping, key: str, kind: type, where: str):
    if key not in table:
        raise RegisterMapError(f"{where}: missing field {key!r}")
    value = table[key]
    if not isinstance(value, kind):
        raise RegisterMapError(f"{where}: {key} must be a {kind.__name__}, got {value!r}")
    return value


def _int_field(table: Mapping, key: str, where: str) -> int:
    value = _field(table, key, int, where)
    if isinstance(value, bool) or value < 0:
        raise RegisterMapError(f"{where}: {key} must be an integer >= 0, got {value!r}")
    return value


def _number(spec: Mapping, key: str, where: str) -> float | None:
    value = spec.get(key)
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise RegisterMapError(f"{where}: {key} must be a finite number, got {value!r}")
    return float(value)


def _register(name: str, spec: object, source: str) -> Register:
    where = f"{source}: [registers.{name}]"
    if not isinstance(spec, Mapping):
        raise RegisterMapError(f"{where}: must be a table")
    table = _field(spec, "table", str, where)
    kind = _field(spec, "type", str, where)
    access = spec.get("access", "r")
    for key, value, allowed in (("table", table, _TABLES), ("type", kind, _TYPES),
                                ("access", access, _ACCESS)):
        if value not in allowed:
            raise RegisterMapError(f"{where}: {key} must be one of {', '.join(allowed)}, "
                                   f"got {value!r}")
    address = _int_field(spec, "address", where)
    if address + _TYPES[kind][1] > 0x10000:
        raise RegisterMapError(f"{where}: address {address} past the 16-bit address space")
    scale = _number(spec, "scale", where)
    if scale is not None and scale <= 0:
        raise RegisterMapError(f"{where}: scale must be > 0, got {scale!r}")
    return Register(name, table, address, kind, 1.0 if scale is None else scale, access,
                    str(spec.get("unit", "")), _number(spec, "min", where),
                    _number(spec, "max", where))


def _text_register(name: str, spec: object, source: str) -> TextRegister:
    where = f"{source}: [identity.{name}]"
    if not isinstance(spec, Mapping):
        raise RegisterMapError(f"{where}: must be a table {{ table, address, count }}")
    unknown = sorted(set(spec) - set(_TEXT_KEYS))
    if unknown:
        raise RegisterMapError(f"{where}: unknown key {unknown[0]!r} (known: "
                               f"{', '.join(_TEXT_KEYS)})")
    table = _field(spec, "table", str, where)
    if table not in _TABLES:
        raise RegisterMapError(f"{where}: table must be one of {', '.join(_TABLES)}, "
                               f"got {table!r}")
    address = _int_field(spec, "address", where)
    count = _int_field(spec, "count", where)
    if not 1 <= count <= MAX_READ_REGISTERS:
        raise RegisterMapError(f"{where}: count must be 1..{MAX_READ_REGISTERS} registers "
                               f"(2 characters each), got {count}")
    if address + count > 0x10000:
        raise RegisterMapError(f"{where}: address {address} past the 16-bit address space")
    return TextRegister(name, table, address, count)


def _check_interlock_bit(bits: Mapping[str, int], source: str) -> None:
    """The optional interlock bit: one of the 16 bits of `status`, shared with no other bit."""
    if "interlock" not in bits:
        return
    bit = bits["interlock"]
    others = [name for name, n in bits.items() if n == bit and name != "interlock"]
    if bit > 15 or others:
        why = f"is also {others[0]!r}" if others else "is past bit 15 of the status register"
        raise RegisterMapError(f"{source}: status_bits.interlock = {bit} {why}")


def _section(table: Mapping, key: str, source: str) -> Mapping:
    """An optional sub-table of the map (empty when absent)."""
    value = table.get(key, {})
    if not isinstance(value, Mapping):
        raise RegisterMapError(f"{source}: [{key}]: must be a table, got {value!r}")
    return value


def _gain_ranges(table: Mapping, source: str) -> tuple[float, ...]:
    ranges = table.get("full_scale_w", [])
    ok = isinstance(ranges, list) and all(
        isinstance(r, int | float) and not isinstance(r, bool) and r > 0 for r in ranges
    ) and all(a < b for a, b in zip(ranges, ranges[1:], strict=False))
    if not ok:
        raise RegisterMapError(f"{source}: [gain_ranges] full_scale_w: must be increasing powers "
                               f"> 0 W, got {ranges!r}")
    return tuple(float(r) for r in ranges)


def _fault_table(table: Mapping, source: str) -> dict[str, dict]:
    out = {}
    for name, spec in table.items():
        where = f"{source}: [fault_codes.{name}]"
        if not isinstance(spec, Mapping):
            raise RegisterMapError(f"{where}: must be a table with code and text")
        out[name] = {"code": _int_field(spec, "code", where),
                     "text": _field(spec, "text", str, where)}
    return out
