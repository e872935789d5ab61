"""Seeded fault injection for emulated devices: latency, dropped or corrupted bytes, bad CRC,
stalled replies, disconnects, (a PM100's) invalid readings and an interlock (an ESP's
emergency stop, a Modbus unit's interlock input), configured per device by a
`[sim.faults.<device>]` table.
"""

from __future__ import annotations

import dataclasses
import math
import random
import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any


class FaultConfigError(ValueError):
    """A fault table with an unknown key or a value out of range (the message names it)."""


_PROBABILITIES = ("drop_prob", "corrupt_prob", "bad_crc_prob", "stall_prob", "invalid_prob")
#: Fault keys only some device kinds act on, with what such a device then does (each kind in
#: sim.device_kinds names those it takes; any other kind refuses them).
KIND_FAULTS = {"invalid_prob": "answers with an invalid reading",
               "interlock": "has an interlock input"}


def _is_number(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


@dataclass(frozen=True)
class InterlockWindow:
    """The device's interlock input opens at start_s and closes duration_s later (seconds of
    the bench's wall clock: since the run started)."""

    start_s: float
    duration_s: float

    @classmethod
    def from_table(cls, table: object) -> InterlockWindow:
        """From `interlock = {start_s, duration_s}` (FaultConfigError naming what is wrong)."""
        if not (isinstance(table, Mapping) and set(table) == {"start_s", "duration_s"}
                and all(_is_number(v) and 0.0 <= v < math.inf for v in table.values())):
            raise FaultConfigError(f"[faults] interlock: must be {{start_s, duration_s}}, numbers "
                                   f">= 0, got {table!r}")
        return cls(float(table["start_s"]), float(table["duration_s"]))

    def holds(self, t_s: float) -> bool:
        """True while the interlock input is open at time t_s."""
        return self.start_s <= t_s < self.start_s + self.duration_s


@dataclass(frozen=True)
class FaultSpec:
    """What goes wrong on one device's replies, and how often (all off by default).

    latency_s: added delay before every reply; *_prob: per-reply probabilities of one
    dropped byte, one corrupted byte (high bit flipped: not valid ASCII, so a host can
    tell), a wrong Modbus CRC, a stalled (never sent) reply; invalid_prob: per reading, the
    meter has none and answers SCPI's not-a-number 9.91E+37 (PM100 only); disconnect_after:
    the device hangs up after this many replies (None = never); interlock: when the device's
    interlock input is open (an InterlockWindow, or its table); seed: the RNG seed.
    """

    latency_s: float = 0.0
    drop_prob: float = 0.0
    corrupt_prob: float = 0.0
    bad_crc_prob: float = 0.0
    stall_prob: float = 0.0
    invalid_prob: float = 0.0
    disconnect_after: int | None = None
    interlock: InterlockWindow | None = None
    seed: int = 0

    def __post_init__(self) -> None:
        if self.interlock is not None and not isinstance(self.interlock, InterlockWindow):
            object.__setattr__(self, "interlock", InterlockWindow.from_table(self.interlock))
        if not (_is_number(self.latency_s) and 0.0 <= self.latency_s < math.inf):
            raise FaultConfigError(
                f"[faults] latency_s: must be a number >= 0, got {self.latency_s!r}"
            )
        for name in _PROBABILITIES:
            value = getattr(self, name)
            if not (_is_number(value) and 0.0 <= value <= 1.0):
                raise FaultConfigError(f"[faults] {name}: must be in [0, 1], got {value!r}")
        n = self.disconnect_after
        if n is not None and not (isinstance(n, int) and not isinstance(n, bool) and n >= 0):
            raise FaultConfigError(f"[faults] disconnect_after: must be an integer >= 0, got {n!r}")
        if not (isinstance(self.seed, int) and not isinstance(self.seed, bool)):
            raise FaultConfigError(f"[faults] seed: must be an integer, got {self.seed!r}")

    @classmethod
    def from_dict(cls, table: Mapping[str, Any], device: str = "") -> FaultSpec:
        """Build from a config table; an unknown key raises FaultConfigError naming it."""
        known = {f.name for f in dataclasses.fields(cls)}
        where = f"[sim.faults.{device}]" if device else "[faults]"
        for key in table:
            if key not in known:
                raise FaultConfigError(
                    f"{where}: unknown key {key!r} (known: {', '.join(sorted(known))})"
                )
        try:
            return cls(**dict(table))
        except FaultConfigError as exc:
            raise FaultConfigError(str(exc).replace("[faults]", where, 1)) from None

    @property
    def active(self) -> bool:
        """True when any fault is switched on."""
        return (
            self.latency_s > 0.0
            or any(getattr(self, name) > 0.0 for name in _PROBABILITIES)
            or self.disconnect_after is not None
        )


class InterlockInput:
    """An emulated device's interlock input, open while its InterlockWindow holds on `clock`
    (seconds). A device polls it as it handles requests: the opening is reported once, however
    briefly it was open between two polls (a real device latches it)."""

    def __init__(self, window: InterlockWindow, clock: Callable[[], float]):
        self.window, self.clock = window, clock
        self._tripped = False

    def poll(self) -> tuple[bool, bool]:
        """(the input opened since the last poll, it is open now)."""
        now = self.clock()
        tripped = not self._tripped and now >= self.window.start_s
        self._tripped = self._tripped or tripped
        return tripped, self.window.holds(now)


class FaultInjector:
    """Applies a FaultSpec to a device's replies with a seeded, thread-safe RNG.

    Each reply draws its faults in a fixed order (stall, drop, corrupt, bad CRC), so a
    given seed and reply sequence always gives the same faults. `seed` (e.g. the bench's
    [sim] seed) is mixed with the spec's own seed when given.
    """

    def __init__(self, spec: FaultSpec | None = None, seed: int | None = None):
        self.spec = spec or FaultSpec()
        mixed = self.spec.seed if seed is None else f"{seed}:{self.spec.seed}"
        self._rng = random.Random(mixed)
        self._lock = threading.Lock()
        self.replies = 0
        self.counts = {"stall": 0, "drop": 0, "corrupt": 0, "bad_crc": 0, "invalid": 0}

    def delay(self) -> float:
        """Seconds (real) to wait before sending a reply."""
        return self.spec.latency_s

    def should_disconnect(self) -> bool:
        """True once the device has sent disconnect_after replies."""
        n = self.spec.disconnect_after
        return n is not None and self.replies >= n

    def reply(self, data: bytes, keep_tail: int = 0, crc_bytes: int = 0) -> bytes | None:
        """The bytes actually sent for a reply, or None for a stalled reply.

        keep_tail: trailing bytes (a line terminator) that drop/corrupt leave alone;
        crc_bytes: trailing CRC bytes that a bad-CRC fault alters (0 = no CRC).
        """
        spec = self.spec
        with self._lock:
            self.replies += 1
            if self._hit(spec.stall_prob, "stall"):
                return None
            out = bytearray(data)
            body = len(out) - keep_tail
            if body > 0 and self._hit(spec.drop_prob, "drop"):
                del out[self._rng.randrange(body)]
                body -= 1
            if body > 0 and self._hit(spec.corrupt_prob, "corrupt"):
                out[self._rng.randrange(body)] ^= 0x80
            if 0 < crc_bytes <= len(out) and self._hit(spec.bad_crc_prob, "bad_crc"):
                out[-1] ^= self._rng.randrange(1, 256)
            return bytes(out)

    def invalid_reading(self) -> bool:
        """True if this reading is to be invalid (drawn only when invalid_prob > 0, so the
        reply faults of a seed are the same with it off)."""
        with self._lock:
            return self._hit(self.spec.invalid_prob, "invalid")

    def _hit(self, prob: float, kind: str) -> bool:
        if prob <= 0.0:
            return False
        hit = self._rng.random() < prob
        self.counts[kind] += hit
        return hit
