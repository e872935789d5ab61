"""Reading SCPI program messages for the instrument emulators: header patterns with short and
long keyword forms, optional nodes and numeric suffixes (SCPI-99 vol. 1, ch. 6), and the
program data a command takes (decimal numbers with MIN / MAX / DEF and unit suffixes,
booleans, non-decimal #H / #Q / #B numbers; ch. 7), each bad input a `ScpiError` carrying
its SCPI error code.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass

SCPI_ERRORS = {
    0: "No error",
    -101: "Invalid character",
    -102: "Syntax error",
    -104: "Data type error",
    -108: "Parameter not allowed",
    -109: "Missing parameter",
    -113: "Undefined header",
    -114: "Header suffix out of range",
    -131: "Invalid suffix",
    -138: "Suffix not allowed",
    -222: "Data out of range",
    -224: "Illegal parameter value",
    -230: "Data corrupt or stale",
    -241: "Hardware missing",
    -350: "Queue overflow",
    -363: "Input buffer overrun",
}
MIN_WORDS = ("MIN", "MINIMUM")
MAX_WORDS = ("MAX", "MAXIMUM")
DEF_WORDS = ("DEF", "DEFAULT")


class ScpiError(Exception):
    """A program message unit the instrument refuses: `code` is its SCPI error number."""

    def __init__(self, code: int):
        super().__init__(f"{code},{SCPI_ERRORS[code]}")
        self.code = code


@dataclass(frozen=True)
class Node:
    """One keyword of a header pattern: its short and long form, whether it may be left out
    and whether it takes a numeric suffix (SENSe1)."""

    short: str
    long: str
    optional: bool
    numbered: bool
    aliases: tuple[str, ...] = ()

    def spells(self, keyword: str) -> bool:
        """True if `keyword` (upper case) is this node's short or long form or an alias."""
        return keyword in (self.short, self.long, *self.aliases)


def pattern(spec: str) -> tuple[Node, ...]:
    """'[SENSe#]:POWer[:DC]:RANGe' -> nodes with short/long forms, optional and numbered
    ('#') flags; 'WAVelength/WAVE' adds a spelling the instrument accepts besides the two
    forms."""
    nodes = []
    for opt, word, aliases, numbered in re.findall(
            r"(\[?):?([A-Za-z*]+)((?:/[A-Z]+)*)(#?)\]?", spec):
        short = "".join(ch for ch in word if ch.isupper() or ch == "*")
        nodes.append(Node(short, word.upper(), bool(opt), bool(numbered),
                          tuple(aliases.split("/")[1:])))
    return tuple(nodes)


Token = tuple[str, str]  # (keyword, numeric suffix or "")


def matches(nodes: tuple[Node, ...], tokens: list[Token]) -> bool:
    """True if the header's tokens spell the pattern (short or long forms, optional nodes
    left out, a suffix only where the pattern allows one)."""
    if not nodes:
        return not tokens
    head, rest = nodes[0], nodes[1:]
    if (tokens and head.spells(tokens[0][0])
            and (head.numbered or not tokens[0][1]) and matches(rest, tokens[1:])):
        return True
    return head.optional and matches(rest, tokens)


_UNIT = re.compile(r"(:?)([A-Za-z*][A-Za-z0-9:*]*)(\?)?(?:\s+(.*))?")
_KEYWORD = re.compile(r"([A-Z*]+)(\d*)")
_NRF = re.compile(r"([+-]?(?:\d+\.?\d*|\.\d+)(?:E[+-]?\d+)?)\s*([A-Z]*)")
_NON_DECIMAL = {"#H": (16, re.compile(r"[0-9A-F]+")), "#Q": (8, re.compile(r"[0-7]+")),
                "#B": (2, re.compile(r"[01]+"))}


@dataclass(frozen=True)
class MessageUnit:
    """One program message unit: rooted (a leading ':'), its header tokens, whether it is a
    query, and its parameters (upper case, stripped)."""

    rooted: bool
    tokens: list[Token]
    query: bool
    args: list[str]

    @property
    def common(self) -> bool:
        """An IEEE 488.2 common command (*IDN?, *RST, ...)."""
        return self.tokens[0][0].startswith("*")


def parse_unit(text: str) -> MessageUnit:
    """A message unit's header and parameters, or ScpiError -102 / -113."""
    match = _UNIT.fullmatch(text)
    if match is None:
        raise ScpiError(-102)
    rooted, header, question, params = match.groups()
    words = header.upper().split(":")
    if any(not w for w in words):
        raise ScpiError(-102)
    keywords = [_KEYWORD.fullmatch(w) for w in words]
    if any(k is None for k in keywords):
        raise ScpiError(-113)
    args = [a.strip().upper() for a in params.split(",")] if params else []
    return MessageUnit(bool(rooted), [(k.group(1), k.group(2)) for k in keywords],
                       question is not None, args)


def no_args(args: list[str]) -> None:
    """A command that takes no parameter: -108 if one came."""
    if args:
        raise ScpiError(-108)


def one_arg(args: list[str]) -> str:
    """The single parameter of a command: -109 if missing, -108 if more came."""
    if not args:
        raise ScpiError(-109)
    if len(args) > 1:
        raise ScpiError(-108)
    return args[0]


def optional_arg(args: list[str]) -> str | None:
    """A query's optional parameter (MIN / MAX / DEF): None if none came."""
    return one_arg(args) if args else None


@dataclass(frozen=True)
class Limits:
    """A numeric setting's bounds and its default (None: DEF is not allowed)."""

    low: float
    high: float
    default: float | None = None

    def word(self, text: str) -> float | None:
        """The value MIN / MAX / DEF stand for (None for any other text; -224 for DEF on a
        setting without one)."""
        if text in MIN_WORDS:
            return self.low
        if text in MAX_WORDS:
            return self.high
        if text in DEF_WORDS:
            if self.default is None:
                raise ScpiError(-224)
            return self.default
        return None


def number(text: str, limits: Limits, units: Mapping[str, float] | None = None) -> float:
    """A decimal numeric parameter (or MIN / MAX / DEF), optionally with one of `units`
    (e.g. 633NM, 633 nm, 1.5 uW), in the parameter's own unit, within the limits (-222)."""
    word = limits.word(text)
    if word is not None:
        return word
    match = _NRF.fullmatch(text)
    if match is None:
        raise ScpiError(-104)
    digits, suffix = match.groups()
    if suffix and units is None:
        raise ScpiError(-138)
    if suffix and suffix not in units:
        raise ScpiError(-131)
    value = float(digits) * (units[suffix] if suffix else 1.0)
    if not (math.isfinite(value) and limits.low <= value <= limits.high):
        raise ScpiError(-222)
    return value


def integer(text: str, limits: Limits, exact: bool = False) -> int:
    """An integer parameter: NRf (rounded, as SCPI allows for register values; with `exact`
    a fraction is -222, as for a count), #H / #Q / #B non-decimal, or MIN / MAX / DEF,
    within the limits (-222)."""
    base = _NON_DECIMAL.get(text[:2])
    if base is None:
        value = number(text, limits)
        if exact and value != int(value):
            raise ScpiError(-222)
        return round(value)
    radix, digits = base
    if digits.fullmatch(text[2:]) is None:
        raise ScpiError(-104)
    value = int(text[2:], radix)
    if not limits.low <= value <= limits.high:
        raise ScpiError(-222)
    return value


def boolean(text: str) -> bool:
    """SCPI boolean program data: ON / OFF, or a number rounded to an integer, nonzero
    being ON (SCPI-99 vol. 1, 7.3)."""
    if text in ("ON", "OFF"):
        return text == "ON"
    match = _NRF.fullmatch(text)
    if match is None or match.group(2):
        raise ScpiError(-104)
    return abs(float(match.group(1))) >= 0.5  # rounds to a nonzero integer


def flag_setting(read: Callable[[], bool], write: Callable[[bool], None]
                 ) -> Callable[[bool, list[str]], str | None]:
    """A boolean setting's command and query (ON / OFF / a number; answers 1 or 0), as a
    command-table action."""
    def access(query: bool, args: list[str]) -> str | None:
        if query:
            no_args(args)
            return "1" if read() else "0"
        write(boolean(one_arg(args)))
        return None
    return access


def attribute_flag(owner: object, name: str) -> Callable[[bool, list[str]], str | None]:
    """flag_setting on the boolean attribute `name` of `owner`."""
    return flag_setting(lambda: getattr(owner, name), lambda on: setattr(owner, name, on))


def choice(text: str, options: tuple[str, ...]) -> str:
    """Character program data: one of `options` given in long or short form (the upper-case
    part), answered in the short form."""
    for option in options:
        short = "".join(ch for ch in option if ch.isupper())
        if text in (short, option.upper()):
            return short
    raise ScpiError(-224)


def nr3(value: float) -> str:
    """A number as the PM100 family answers it: NR3 with six decimals (1.234567E-06)."""
    return f"{value:.6E}"


def limits_query(args: list[str], limits: Limits, now: float) -> str:
    """A setting's '?': its value now, or with MIN / MAX / DEF its bounds or default."""
    word = optional_arg(args)
    if word is None:
        return nr3(now)
    value = limits.word(word)
    if value is None:
        raise ScpiError(-224)
    return nr3(value)
