"""Emulated Modbus stepper drive moving a rotation stage, per its register map.

Motion runs on the shared virtual clock (trapezoidal profiles). Settings are stored as
written and checked when a command uses them: a bad one refuses the command and shows in
`fault_code` and the fault bit (limit bit too for a target past a software limit).
"""

from __future__ import annotations

from pathlib import Path

from sim.devices.faults import FaultSpec, InterlockInput
from sim.devices.modbus_server import EmulatedUnit
from sim.devices.motion import LimitError, TrapezoidAxis, VirtualClock
from sim.devices.register_map import DeviceLayout, Field

_FIELDS = ("target_position", "velocity", "acceleration", "command", "fault_code",
           "actual_position", "status", "limit_negative", "limit_positive")
_COMMANDS = ("start", "stop", "home", "abort", "clear_fault")
_BITS = ("moving", "homed", "limit", "fault")
_FAULTS = ("limit", "velocity", "acceleration", "limits")


class _Refused(Exception):
    """A command the drive refuses; `fault` names the map's fault code."""

    def __init__(self, fault: str):
        self.fault = fault
        super().__init__(fault)


class ModbusStageEmulator(EmulatedUnit):
    """One stepper drive unit: a TrapezoidAxis behind the map's registers (degrees); serial
    and device_identification as for EmulatedUnit; interlock: the drive's interlock input
    (when it opens the drive stops at once; while it is open the map's `interlock` status bit
    is set and start and home are ignored)."""

    def __init__(self, clock: VirtualClock, register_map_path: str | Path,
                 limits_deg: tuple[float, float], speed_deg_s: float, accel_deg_s2: float,
                 faults: FaultSpec | None = None, position_deg: float = 0.0, *,
                 serial: str | None = None, device_identification: bool = True,
                 interlock: InterlockInput | None = None):
        layout = DeviceLayout.read(register_map_path)
        layout.need(_FIELDS, _COMMANDS, _BITS, _FAULTS)
        super().__init__(layout, faults, serial=serial,
                         device_identification=device_identification)
        self.axis = TrapezoidAxis(clock, speed_deg_s, accel_deg_s2, tuple(limits_deg),
                                  position_deg)  # homes to 0, or the nearest limit
        for name, value in (("velocity", speed_deg_s), ("acceleration", accel_deg_s2),
                            ("limit_negative", limits_deg[0]), ("limit_positive", limits_deg[1]),
                            ("target_position", position_deg)):
            self.registers.set(name, value)
        self.fault: str | None = None
        self.limit_hit = False
        self.interlock, self.interlocked = interlock, False

    def axis_position_deg(self) -> float:
        """Actual position now, degrees (what a bench model looks at)."""
        return self.axis.position()

    def _watch_interlock(self) -> None:
        if self.interlock is None:
            return
        tripped, self.interlocked = self.interlock.poll()
        if tripped:
            self.axis.abort()

    def refresh(self, fields: list[Field]) -> None:
        self._watch_interlock()
        names = {f.name for f in fields}
        # status before position: the clock runs on between the two, and a "not moving" read
        # first guarantees the position read next is the final one
        if "status" in names:
            flags = {"moving": self.axis.is_moving(), "homed": self.axis.homed,
                     "limit": self.limit_hit, "fault": self.fault is not None,
                     "interlock": self.interlocked}
            self.registers.set("status", sum(1 << self.layout.bits[b] for b, on in flags.items()
                                             if on and b in self.layout.bits))
        if "actual_position" in names:
            self.registers.set("actual_position", self.axis.position())
        if "fault_code" in names:
            code = self.layout.faults[self.fault][0] if self.fault else 0
            self.registers.set("fault_code", code)

    def act(self, fields: list[Field]) -> None:
        if "command" not in {f.name for f in fields}:
            return
        self._watch_interlock()
        command = self.take_command()
        if command in ("start", "home") and self.interlocked:
            return
        if command == "stop":
            self.axis.stop()
        elif command == "abort":
            self.axis.abort()
        elif command == "clear_fault":
            self.fault, self.limit_hit = None, False
        else:
            self._move(command)

    def _move(self, command: str) -> None:
        """Start or home with the stored settings, or refuse with a fault code."""
        try:
            self._apply_settings()
            if command == "start":
                self.axis.move_to(self.registers.get("target_position"))
            else:
                self.axis.home()
        except _Refused as exc:
            self.fault, self.limit_hit = exc.fault, False
            return
        except LimitError:
            self.fault, self.limit_hit = "limit", True
            return
        self.fault, self.limit_hit = None, False

    def _apply_settings(self) -> None:
        values = {n: self.registers.get(n) for n in ("velocity", "acceleration",
                                                     "limit_negative", "limit_positive")}
        for name in ("velocity", "acceleration"):
            f = self.layout.fields[name]
            if not (f.low <= values[name] <= f.high and values[name] > 0):
                raise _Refused(name)
        if not values["limit_negative"] < values["limit_positive"]:
            raise _Refused("limits")
        self.axis.speed = values["velocity"]
        self.axis.accel = values["acceleration"]
        self.axis.limits = (values["limit_negative"], values["limit_positive"])
