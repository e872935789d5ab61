"""Rotation stage on a Modbus stepper drive (RTU or TCP), addressed through its register map.

Implements drivers.base.Axis (and Interlock, through the map's optional `interlock` status bit:
a move or wait that finds it set raises Interlocked). Motion commands are written once; if the
reply to one is lost the driver re-reads the drive's state to learn whether it was taken,
instead of sending it again.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from drivers.base import DeviceError
from drivers.lost_reply import reraise, sent_once
from drivers.modbus_unit import MappedUnit
from drivers.polling import poll_until
from drivers.register_map import RegisterMap

STAGE_REGISTERS = ("target_position", "velocity", "acceleration", "command", "fault_code",
                   "actual_position", "status", "limit_negative", "limit_positive")
STAGE_COMMANDS = ("start", "stop", "home", "abort", "clear_fault")
STAGE_BITS = ("moving", "homed", "limit", "fault")
MOTION = ("velocity", "acceleration")  # the settings of the next move, deg/s and deg/s^2
LIMITS = ("limit_negative", "limit_positive")  # software travel limits, deg


class ModbusStage(MappedUnit):
    """One rotation axis on a Modbus stepper drive; positions in degrees."""

    kind_name = "modbus-stage"
    needs = (STAGE_REGISTERS, STAGE_COMMANDS, STAGE_BITS)

    def __init__(self, transport: str, port_or_host: str, unit: int,
                 register_map: str | Path | RegisterMap, *, poll_s: float = 0.005,
                 **link: Any):
        """`link`: MappedUnit's keywords (name, tcp_port, line, timeouts, read_retries);
        poll_s: the pause between status reads while waiting for a move."""
        super().__init__(transport, port_or_host, unit, register_map, **link)
        self.poll_s = poll_s

    # -- state ------------------------------------------------------------------
    def status(self) -> dict[str, bool]:
        """The drive's status bits by name (moving, homed, limit, fault)."""
        return self.bits(self.read_value("status"))

    def position(self) -> float:
        """Actual position now, degrees."""
        return self.read_value("actual_position")

    def is_moving(self) -> bool:
        """True while a move, stop or home is under way."""
        return self.status()["moving"]

    def homed(self) -> bool:
        """True once a home has completed."""
        return self.status()["homed"]

    def fault(self) -> tuple[int, str]:
        """The drive's fault code and the map's text for it ((0, ...) = no fault)."""
        code = int(self.read_value("fault_code"))
        return code, "no fault" if code == 0 else self.map.fault_text(code)

    def limits(self) -> tuple[float, float]:
        """The drive's software travel limits, degrees."""
        return self.read_tuple(LIMITS)

    # -- settings ---------------------------------------------------------------
    def configure(self, speed_deg_s: float, accel_deg_s2: float,
                  limits_deg: tuple[float, float]) -> None:
        """The Axis settings: speed and acceleration (set_motion), then travel limits."""
        self.set_motion(speed_deg_s, accel_deg_s2)
        self.set_limits(*limits_deg)

    def set_motion(self, speed_deg_s: float, accel_deg_s2: float) -> None:
        """Set the cruise speed and acceleration used by the next move (map range checked)."""
        self.write_values(dict(zip(MOTION, (speed_deg_s, accel_deg_s2), strict=True)))

    def motion(self) -> tuple[float, float]:
        """(speed_deg_s, accel_deg_s2) the drive holds."""
        return self.read_tuple(MOTION)

    def set_limits(self, low_deg: float, high_deg: float) -> None:
        """Set the software travel limits (the drive checks low < high on the next move)."""
        self.write_values(dict(zip(LIMITS, (low_deg, high_deg), strict=True)))

    # -- motion -----------------------------------------------------------------
    def move_to(self, position_deg: float) -> None:
        """Start an absolute move; DeviceError if the drive refuses it (e.g. past a limit)."""
        if not math.isfinite(position_deg):
            raise ValueError(f"{self.name}: target must be a finite angle, got {position_deg!r}")
        self.write_value("target_position", position_deg)
        self._motion_command("start", position_deg)

    def home(self) -> None:
        """Start homing (a move to 0, or the drive's nearest limit, that sets the homed bit);
        wait() waits for it."""
        self._motion_command("home", None)

    def stop(self) -> None:
        """Decelerate to rest; harmless at rest."""
        self.command("stop")

    def abort(self) -> None:
        """Stop at once without deceleration."""
        self.command("abort")

    def clear_fault(self) -> None:
        """Clear the drive's fault code and fault / limit bits."""
        self.command("clear_fault")

    def wait(self, timeout_s: float) -> float:
        """Poll until the drive is at rest; return the final position (DeviceTimeout past
        timeout_s, DeviceError if the drive reports a fault)."""
        def at_rest() -> float | None:
            v = self.read_values("status", "fault_code", "actual_position")
            bits = self.bits(v["status"])
            self.check_interlock(bits)
            if bits["fault"]:
                self._raise_fault(int(v["fault_code"]))
            return None if bits["moving"] else v["actual_position"]

        return poll_until(at_rest, timeout_s, self.poll_s, self.name, "end of motion")

    def _motion_command(self, command: str, target_deg: float | None) -> None:
        """Write a motion command once; a lost or garbled reply is resolved by reading the
        state (unresolved, the lost reply's error stands)."""
        sent_once(lambda: self.command(command), lambda: self._was_taken(target_deg), reraise)
        v = self.read_values("status", "fault_code")
        bits = self.bits(v["status"])
        self.check_interlock(bits)
        if bits["fault"]:
            self._raise_fault(int(v["fault_code"]))

    def _was_taken(self, target_deg: float | None) -> bool:
        """After a lost reply: did the drive take the command (moving, refused with a fault,
        or already there: at the target, or homed for a home)?"""
        v = self.read_values("status", "actual_position")
        bits = self.bits(v["status"])
        if target_deg is None:
            there = bits["homed"]
        else:
            step = 1.0 / self.map.register("actual_position").scale
            there = abs(v["actual_position"] - target_deg) <= step
        return bits["moving"] or bits["fault"] or there

    def _raise_fault(self, code: int) -> None:
        raise DeviceError(self.name, code, self.map.fault_text(code))
