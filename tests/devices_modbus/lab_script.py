"""What a lab's own Modbus script knows, for the third-party client tests: the register map as
tomllib reads it (never gonio's map readers), the Modbus spec's exception names, a move polled
to its end on the drive's virtual clock, and how many polls its trapezoid takes."""

from __future__ import annotations

import math
import tomllib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from sim.devices.motion import VirtualClock

POLL_STEP_S = 0.25  # virtual seconds a script waits between two status polls
# Modbus Application Protocol V1.1b3, section 7: the exception codes a unit answers with
SPEC_EXCEPTIONS = {1: "illegal function", 2: "illegal data address", 3: "illegal data value",
                   11: "gateway target device failed to respond"}


@dataclass(frozen=True)
class LabMap:
    """A register-map file as a script written from the device's documentation reads it."""

    doc: dict

    @classmethod
    def load(cls, path: Path) -> LabMap:
        """Parse the map file with tomllib."""
        with open(path, "rb") as f:
            return cls(tomllib.load(f))

    @property
    def big_endian(self) -> bool:
        """True when the high word of a 32-bit value comes first."""
        return self.doc["word_order"] == "big"

    def address(self, register: str) -> int:
        """Protocol address of a register."""
        return self.doc["registers"][register]["address"]

    def raw(self, register: str, value: float) -> int:
        """The register's integer for an engineering value (raw = round(value * scale))."""
        return round(value * self.doc["registers"][register].get("scale", 1.0))

    def value(self, register: str, raw: int) -> float:
        """The engineering value of a register's integer."""
        return raw / self.doc["registers"][register].get("scale", 1.0)

    def bit(self, name: str) -> int:
        """Mask of a status bit."""
        return 1 << self.doc["status_bits"][name]

    def command(self, name: str) -> int:
        """Value to write to the command register."""
        return self.doc["commands"][name]

    def fault(self, name: str) -> int:
        """Code of a fault in fault_code."""
        return self.doc["fault_codes"][name]["code"]

    def identity(self, name: str) -> tuple[int, int]:
        """(address, register count) of an identity string."""
        entry = self.doc["identity"][name]
        return entry["address"], entry["count"]


def ascii_of(text: str | bytes | list[int]) -> str:
    """An identity string as a script shows it, from a library's string, bytes or registers
    (two characters a register, the first in the high byte): NUL and space padding stripped."""
    if isinstance(text, list):
        text = b"".join(word.to_bytes(2, "big") for word in text)
    if isinstance(text, bytes):
        text = text.decode("ascii")
    return text.strip("\0 ")


def moving_polls(distance_deg: float, speed_deg_s: float, accel_deg_s2: float,
                 step_s: float = POLL_STEP_S) -> int:
    """Status polls, one every step_s from the start, that see a rest-to-rest trapezoid move
    (acceleration = deceleration, full speed reached) still moving."""
    assert abs(distance_deg) >= speed_deg_s ** 2 / accel_deg_s2, "no cruise: pick a longer move"
    return math.ceil((abs(distance_deg) / speed_deg_s + speed_deg_s / accel_deg_s2) / step_s)


def check_move(positions_deg: list[float], start_deg: float, target_deg: float) -> None:
    """Positions polled during a move run monotonically from the start to the target."""
    ahead = [(target_deg - p) * math.copysign(1.0, target_deg - start_deg) for p in positions_deg]
    assert all(a >= b for a, b in zip(ahead, ahead[1:], strict=False)), positions_deg
    assert ahead[0] > 0.0 and positions_deg[-1] == target_deg, positions_deg


def poll_move(lab: LabMap, status: Callable[[], int], position_deg: Callable[[], float],
              clock: VirtualClock, step_s: float = POLL_STEP_S,
              most: int = 100) -> tuple[int, list[float]]:
    """Poll status, then position, advancing the drive's clock step_s after each poll that
    sees the moving bit (where a script would sleep); returns (those polls, the positions)."""
    positions = []
    for polls in range(most):
        moving = status() & lab.bit("moving")
        positions.append(position_deg())  # read after status: the last is where it stopped
        if not moving:
            return polls, positions
        clock.advance(step_s)
    raise AssertionError(f"still moving after {most} polls: {positions[-3:]}")
