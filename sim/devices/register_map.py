"""The emulators' own reader of a register-map file, and the register memory it lays out.

Written apart from drivers.register_map on purpose (a driver bug cannot hide behind shared
code). `DeviceLayout` parses the TOML; `RegisterFile` holds a unit's 16-bit words per
table and answers reads and writes the way a device does: a Modbus exception code for an
address outside the map or a write to a read-only register. A map's optional `interlock` status
bit is the one an emulated unit sets while its interlock fault holds. The map's `[identity]` strings
are read-only registers of ASCII, two characters each (first in the high byte), NUL padded.
A detector map's `sample_s` is how long one averaged sample takes (a reading: averaging x it).
"""

from __future__ import annotations

import math
import struct
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

# Modbus exception codes a unit answers with.
ILLEGAL_FUNCTION = 1
ILLEGAL_ADDRESS = 2
ILLEGAL_VALUE = 3

_FORMATS = {"uint16": ">H", "int16": ">h", "uint32": ">I", "int32": ">i", "float32": ">f"}


class LayoutError(ValueError):
    """A register-map file the emulator cannot use (the message names file and field)."""


class Rejected(Exception):
    """A request the unit answers with a Modbus exception (`code`)."""

    def __init__(self, code: int, why: str):
        self.code = code
        super().__init__(f"exception {code}: {why}")


@dataclass(frozen=True)
class Field:
    """Where a named value lives and how it is coded."""

    name: str
    table: str
    address: int
    fmt: str
    scale: float
    writable: bool
    low: float
    high: float

    @property
    def width(self) -> int:
        """Registers the value occupies."""
        return struct.calcsize(self.fmt) // 2

    def span(self) -> range:
        """The register addresses the value occupies."""
        return range(self.address, self.address + self.width)


@dataclass
class DeviceLayout:
    """A register map as the emulator sees it."""

    source: str
    swap_words: bool
    fields: dict[str, Field]
    commands: dict[str, int]
    bits: dict[str, int]
    faults: dict[str, tuple[int, str]]
    ranges_w: tuple[float, ...] = field(default_factory=tuple)
    identity: dict[str, Field] = field(default_factory=dict)
    model: str = ""
    vendor: str = ""
    sample_s: float = 0.0  # seconds one averaged sample takes (the map's `sample_s`)

    @classmethod
    def read(cls, path: str | Path) -> DeviceLayout:
        """Parse a map file; LayoutError on anything the emulator cannot serve."""
        path = Path(path)
        try:
            doc = tomllib.loads(path.read_text())
        except (OSError, tomllib.TOMLDecodeError) as exc:
            raise LayoutError(f"{path}: {exc}") from None
        src = str(path)
        order = doc.get("word_order")
        if order not in ("big", "little"):
            raise LayoutError(f"{src}: word_order must be big or little, got {order!r}")
        try:
            fields = {n: _field(n, spec) for n, spec in doc.get("registers", {}).items()}
            faults = {n: (int(s["code"]), str(s["text"]))
                      for n, s in doc.get("fault_codes", {}).items()}
            ranges = tuple(float(r) for r in doc.get("gain_ranges", {}).get("full_scale_w", ()))
            commands = {str(n): int(v) for n, v in doc.get("commands", {}).items()}
            bits = {str(n): int(v) for n, v in doc.get("status_bits", {}).items()}
            identity = {n: _text_field(n, spec) for n, spec in doc.get("identity", {}).items()}
            sample_s = float(doc.get("sample_s", 0.0))
        except (AttributeError, KeyError, TypeError, ValueError) as exc:
            raise LayoutError(f"{src}: bad register map entry: {exc!r}") from None
        if "interlock" in bits and (not 0 <= bits["interlock"] <= 15 or list(
                bits.values()).count(bits["interlock"]) > 1):
            raise LayoutError(f"{src}: status bit interlock {bits['interlock']} is not a bit of "
                              f"its own in the 16-bit status register")
        if not 0.0 <= sample_s < math.inf:
            raise LayoutError(f"{src}: sample_s must be a number of seconds >= 0, got {sample_s!r}")
        return cls(src, order == "little", fields, commands, bits, faults, ranges, identity,
                   str(doc.get("name", "")), str(doc.get("vendor", "")), sample_s)

    def need(self, fields: tuple[str, ...], commands: tuple[str, ...],
             bits: tuple[str, ...], faults: tuple[str, ...]) -> None:
        """LayoutError naming the first thing the emulated device needs and the map lacks."""
        for kind, names, have in (("register", fields, self.fields),
                                  ("command", commands, self.commands),
                                  ("status bit", bits, self.bits),
                                  ("fault code", faults, self.faults)):
            for name in names:
                if name not in have:
                    raise LayoutError(f"{self.source}: the map has no {kind} {name!r}")

    def to_words(self, name: str, value: float) -> list[int]:
        """Engineering value -> the words stored in the registers."""
        f = self.fields[name]
        raw = value * f.scale
        if f.fmt != ">f":
            raw = int(round(raw))
            bits = struct.calcsize(f.fmt) * 8
            lo, hi = (0, 2**bits - 1) if f.fmt.isupper() else (-(2 ** (bits - 1)),
                                                                 2 ** (bits - 1) - 1)
            raw = min(max(raw, lo), hi)  # a device register saturates rather than wraps
        packed = struct.pack(f.fmt, raw)
        words = [packed[i] << 8 | packed[i + 1] for i in range(0, len(packed), 2)]
        return words[::-1] if self.swap_words else words

    def from_words(self, name: str, words: list[int]) -> float:
        """The words stored in the registers -> engineering value."""
        f = self.fields[name]
        ordered = words[::-1] if self.swap_words else words
        packed = bytes(b for w in ordered for b in (w >> 8, w & 0xFF))
        return struct.unpack(f.fmt, packed)[0] / f.scale


def _field(name: str, spec: dict) -> Field:
    kind = spec["type"]
    if kind not in _FORMATS:
        raise ValueError(f"register {name}: unknown type {kind!r}")
    table = spec["table"]
    if table not in ("holding", "input"):
        raise ValueError(f"register {name}: unknown table {table!r}")
    scale = float(spec.get("scale", 1.0))
    if not scale > 0:
        raise ValueError(f"register {name}: scale must be > 0")
    return Field(name, table, int(spec["address"]), _FORMATS[kind], scale,
                 spec.get("access", "r") == "rw", float(spec.get("min", -math.inf)),
                 float(spec.get("max", math.inf)))


def _text_field(name: str, spec: dict) -> Field:
    """An [identity] string: `count` read-only registers of ASCII."""
    missing = [key for key in ("table", "address", "count") if key not in spec]
    if missing:
        raise ValueError(f"identity {name}: missing {missing[0]!r}")
    table, count = spec["table"], int(spec["count"])
    if table not in ("holding", "input"):
        raise ValueError(f"identity {name}: unknown table {table!r}")
    if not 1 <= count <= 125:
        raise ValueError(f"identity {name}: count must be 1..125 registers, got {count}")
    return Field(f"identity.{name}", table, int(spec["address"]), f">{2 * count}s", 1.0,
                 False, -math.inf, math.inf)


class RegisterFile:
    """A unit's register memory: words per (table, address), per the layout.

    `read` and `write` raise Rejected for an address the map does not cover, or a write
    touching a read-only register; they move words only (the device decides what they mean).
    """

    def __init__(self, layout: DeviceLayout):
        self.layout = layout
        self.words: dict[tuple[str, int], int] = {}
        self.owner: dict[tuple[str, int], Field] = {}
        for f in (*layout.fields.values(), *layout.identity.values()):
            for addr in f.span():
                key = (f.table, addr)
                if key in self.owner:
                    raise LayoutError(f"{layout.source}: {f.name} overlaps "
                                      f"{self.owner[key].name} at {f.table} {addr}")
                self.owner[key] = f
                self.words[key] = 0

    def fields_in(self, table: str, address: int, count: int) -> list[Field]:
        """The fields a request touches (Rejected if an address is not in the map)."""
        touched: list[Field] = []
        for addr in range(address, address + count):
            f = self.owner.get((table, addr))
            if f is None:
                raise Rejected(ILLEGAL_ADDRESS, f"{table} register {addr} is not in the map")
            if f not in touched:
                touched.append(f)
        return touched

    def read(self, table: str, address: int, count: int) -> list[int]:
        """Stored words of a range."""
        self.fields_in(table, address, count)
        return [self.words[(table, a)] for a in range(address, address + count)]

    def write(self, address: int, values: list[int]) -> list[Field]:
        """Store words into holding registers; returns the fields touched."""
        touched = self.fields_in("holding", address, len(values))
        for f in touched:
            if not f.writable:
                raise Rejected(ILLEGAL_ADDRESS, f"register {f.name} is read-only")
        for offset, word in enumerate(values):
            self.words[("holding", address + offset)] = word & 0xFFFF
        return touched

    def get(self, name: str) -> float:
        """Engineering value of a field."""
        f = self.layout.fields[name]
        return self.layout.from_words(name, [self.words[(f.table, a)] for a in f.span()])

    def set_text(self, name: str, text: str) -> None:
        """Store an [identity] string (ASCII, cut to fit, NUL padded)."""
        f = self.layout.identity[name]
        raw = text.encode("ascii", "replace")[:2 * f.width].ljust(2 * f.width, b"\0")
        for offset, addr in enumerate(f.span()):
            self.words[(f.table, addr)] = int.from_bytes(raw[2 * offset:2 * offset + 2], "big")

    def set(self, name: str, value: float) -> None:
        """Store an engineering value into a field (the device's own update)."""
        f = self.layout.fields[name]
        for addr, word in zip(f.span(), self.layout.to_words(name, value), strict=True):
            self.words[(f.table, addr)] = word
