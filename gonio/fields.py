"""Typed reading of TOML tables with one-line errors naming the file, the table and the key.

Configs and plans both use it, so every bad field is reported the same way, `FILE: [TABLE]
KEY: message` (location()), and an unknown key (a typo) is an error rather than silently
ignored.
"""

from __future__ import annotations

import difflib
import math
import tomllib
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from drivers.user_file import SETTINGS_FILE_CAP, read_user_text
from gonio.errors import GonioError

REQUIRED = object()


def location(source: str, table: str = "", key: str = "") -> str:
    """Where a value is, as every error names it: `FILE: [TABLE] KEY`, leaving out what does
    not apply (`FILE: KEY` at the top level, `FILE: [TABLE]` for a whole table)."""
    place = " ".join(part for part in (f"[{table}]" if table else "", key) if part)
    return f"{source}: {place}" if place else source


class Fields:
    """One TOML table being read: each accessor checks type and range, `done()` rejects extras.

    source: the file (or "config", "plan"); name: the table's dotted TOML name, "" at the top
    level ("detector", "axes.arm", "grid[0]" for an array of tables' first); prefix: the key
    path of an inline table within it ("theta_o_deg.")."""

    def __init__(self, table: Any, source: str, error: type[GonioError], name: str = "",
                 prefix: str = ""):
        self.source, self.name, self.prefix, self.error = source, name, prefix, error
        self.where = location(source, name, prefix.rstrip("."))
        if not isinstance(table, Mapping):
            raise error(f"{self.where}: must be a table, got {_show(table)}")
        self.table = table
        self._used: set[str] = set()

    def fail(self, key: str, message: str) -> GonioError:
        """The error for `key` (raise it)."""
        return self.error(f"{location(self.source, self.name, self.prefix + key)}: {message}")

    def has(self, key: str) -> bool:
        """True if the key is present (and marks it known)."""
        self._used.add(key)
        return key in self.table

    def _get(self, key: str, default: Any) -> Any:
        self._used.add(key)
        if key in self.table:
            return self.table[key]
        if default is REQUIRED:
            near = difflib.get_close_matches(key, [k for k in self.table if isinstance(k, str)],
                                             n=1, cutoff=0.75)
            typo = f" (is {near[0]!r} a typo for it?)" if near else ""
            raise self.error(f"{self.where}: missing required key {key!r}{typo}")
        return default

    def number(
        self,
        key: str,
        default: Any = REQUIRED,
        low: float = -math.inf,
        high: float = math.inf,
        integer: bool = False,
        low_open: bool = False,
    ) -> Any:
        """A finite number (an int if `integer`) in [low, high] (or (low, high] if low_open)."""
        value = self._get(key, default)
        if value is default and key not in self.table:
            return value
        return check_number(value, self.fail, key, low, high, integer, low_open)

    def string(self, key: str, default: Any = REQUIRED, choices: tuple[str, ...] = ()) -> Any:
        """A string, one of `choices` when given."""
        value = self._get(key, default)
        if value is default and key not in self.table:
            return value
        if not isinstance(value, str):
            raise self.fail(key, f"must be a string, got {_show(value)}")
        if choices and value not in choices:
            raise self.fail(key, f"must be one of {', '.join(choices)}; got {value!r}")
        return value

    def boolean(self, key: str, default: Any = REQUIRED) -> Any:
        """A true/false value."""
        value = self._get(key, default)
        if not isinstance(value, bool):
            raise self.fail(key, f"must be true or false, got {_show(value)}")
        return value

    def pair(self, key: str, default: Any = REQUIRED, low: float = -math.inf,
             high: float = math.inf) -> Any:
        """Two increasing finite numbers [lo, hi], each in [low, high]."""
        value = self._get(key, default)
        if value is default and key not in self.table:
            return value
        if not (isinstance(value, list) and len(value) == 2):
            raise self.fail(key, f"must be a list [lo, hi] of two numbers, got {_show(value)}")
        lo, hi = (check_number(v, self.fail, key, low, high) for v in value)
        if not lo < hi:
            raise self.fail(key, f"must have lo < hi, got [{lo:g}, {hi:g}]")
        return lo, hi

    def values(self, key: str, default: Any = REQUIRED, low: float = -math.inf,
               high: float = math.inf) -> Any:
        """A non-empty list of numbers or a range table {start, stop, step | num}, stop included."""
        value = self._get(key, default)
        if value is default and key not in self.table:
            return value
        if isinstance(value, bool) or isinstance(value, int | float):
            value = [value]
        if isinstance(value, list):
            if not value:
                raise self.fail(key, "must not be empty")
            return tuple(check_number(v, self.fail, key, low, high) for v in value)
        if isinstance(value, Mapping):
            return _range(Fields(value, self.source, self.error, self.name,
                                 f"{self.prefix}{key}."), low, high)
        raise self.fail(key, f"must be a number, a list of numbers or a table "
                             f"{{start, stop, step}}, got {_show(value)}")

    def table_of(self, key: str) -> Fields:
        """A sub-table (empty if absent)."""
        name = f"{self.name}.{key}" if self.name else key
        return Fields(self._get(key, {}), self.source, self.error, name)

    def done(self) -> None:
        """Reject any key no accessor asked for."""
        unknown = sorted(set(self.table) - self._used)
        if unknown:
            known = ", ".join(sorted(self._used)) or "none"
            raise self.error(f"{self.where}: unknown key {unknown[0]!r} (known: {known})")


def check_number(value: Any, fail: Any, key: str, low: float = -math.inf,
                 high: float = math.inf, integer: bool = False, low_open: bool = False) -> Any:
    """Check one number; `fail(key, message)` builds the error."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise fail(key, f"must be {'an integer' if integer else 'a number'}, got {_show(value)}")
    if integer and not isinstance(value, int):
        raise fail(key, f"must be an integer, got {value!r}")
    if not math.isfinite(value):
        raise fail(key, f"must be finite, got {value!r}")
    below = value <= low if low_open else value < low
    if below or value > high:
        lo_br = "(" if low_open else "["
        raise fail(key, f"must be in {lo_br}{low:g}, {high:g}], got {value!r}")
    return value if integer else float(value)


def _range(f: Fields, low: float, high: float) -> tuple[float, ...]:
    start = f.number("start", low=low, high=high)
    stop = f.number("stop", low=low, high=high)
    has_step, has_num = f.has("step"), f.has("num")
    if has_step == has_num:
        raise f.error(f"{f.where}: give exactly one of 'step' or 'num'")
    if has_step:
        step = f.number("step", low=0.0, low_open=True)
        n = math.floor(abs(stop - start) / step + 1e-9) + 1
        if n > 100_000:
            raise f.fail("step", f"gives {n} values; at most 100000")
        vals = start + math.copysign(step, stop - start) * np.arange(n)
    else:
        n = f.number("num", low=1, high=100_000, integer=True)
        vals = np.linspace(start, stop, n)
    f.done()
    return tuple(float(v) for v in vals)


def _show(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def read_toml(path: Path, what: str, error: type[GonioError]) -> dict[str, Any]:
    """The table of the TOML file `path` (a `what`: "plan", "instrument config"), or one
    error naming the file: unreadable, not a regular file of bounded size
    (drivers.user_file), not text, or not TOML."""
    text = read_user_text(path, what, SETTINGS_FILE_CAP, error)
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise error(f"{path}: not valid TOML ({exc})") from None


def stored_table(raw: Mapping[str, Any], key: str, where: str, error: type[GonioError],
                 parse: Callable[[Fields], Any]) -> Any:
    """`parse` of the [key] table of a stored (raw) file named `where`, or None if it has
    none (a run's [optics], [sample])."""
    if key not in raw:
        return None
    return parse(Fields(raw[key], where, error, key))
