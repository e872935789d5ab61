"""One emulated ESP301 axis: its trapezoidal motion plus the controller's per-axis settings.

The settings that only configure hardware the emulator idealises (servo gains, driver current,
encoder resolution, fault configuration words) are stored, range-checked and read back as the
manual describes them (ESP301 user's manual EDH0235En1030, section 3.7); `STORED_SETTINGS`
says which, with their ranges. Values are kept in degrees and converted to the axis's SN units.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

from sim.devices.motion import TrapezoidAxis, VirtualClock

# SN unit codes (ESP301 manual, SN command): only the angular ones make sense on a rotary
# stage; value in that unit per degree.
ANGULAR_UNITS = {7: 1.0, 8: 400.0 / 360.0, 9: math.pi / 180.0, 10: 1e3 * math.pi / 180.0,
                 11: 1e6 * math.pi / 180.0}
DEGREE = 7
LARGEST = 2e9  # the manual's upper bound of most settings ("0 to 2e9")

AXIS_KEYS = {
    "limits_deg": (-170.0, 170.0),
    "speed_deg_s": 20.0,
    "accel_deg_s2": 80.0,
    "decel_deg_s2": None,  # None = accel_deg_s2
    "position_deg": 0.0,
    "max_speed_deg_s": 200.0,  # VU: VA above it is error x10
    "max_accel_deg_s2": 2000.0,  # AU: AC/AG above it is error x11
    "motor_on": False,  # the controller powers up with motors off (MO turns them on)
    "stage_id": None,  # ID? answer "model, SNserial"; None = "ROTARY-EMU, SN000<axis>"
}


class EspConfigError(ValueError):
    """An invalid axis table for the emulator (the message names the key)."""


class Fail(Exception):
    """A command failed with an ESP error code (buffered for TE?/TB?, never answered)."""

    def __init__(self, code: int):
        self.code = code


@dataclass(frozen=True)
class StoredSetting:
    """A per-axis setting kept and read back: its kind, default and the manual's range.

    kind: "float", "int" or "hex" (configuration words, answered as hex digits and `H`);
    scaled: in the axis's SN units (stored in degrees); high: a number, or "VU" (the
    axis's maximum speed, exceeding it is error x10) or "above AG" for AE's lower bound.
    """

    kind: str
    default: float
    low: float = 0.0
    high: float | str = LARGEST
    scaled: bool = False


STORED_SETTINGS: dict[str, StoredSetting] = {
    "AE": StoredSetting("float", math.nan, low=math.nan, scaled=True),  # AG .. 2e9; default AU
    "AF": StoredSetting("float", 0.0),
    "BA": StoredSetting("float", 0.0, high=10000.0, scaled=True),  # x SU: 10000 counts
    "CL": StoredSetting("int", 0.0, high=60000.0),
    "CO": StoredSetting("float", 0.0),
    "DB": StoredSetting("int", 0.0),
    "FE": StoredSetting("float", 1.0, scaled=True),
    "FP": StoredSetting("int", 5.0, high=7.0),
    "FR": StoredSetting("float", 0.001, low=2e-9, scaled=True),
    "JH": StoredSetting("float", math.nan, high="VU", scaled=True),  # default VA
    "JK": StoredSetting("float", math.nan, scaled=True),  # default 10 x AC
    "JW": StoredSetting("float", math.nan, high="VU", scaled=True),  # default VA / 10
    "KD": StoredSetting("float", 0.0),
    "KI": StoredSetting("float", 0.0),
    "KP": StoredSetting("float", 0.0),
    "KS": StoredSetting("float", 0.0),
    "OH": StoredSetting("float", math.nan, high="VU", scaled=True),  # default VA
    "OL": StoredSetting("float", math.nan, high="VU", scaled=True),  # default VA / 10
    "OM": StoredSetting("int", 0.0, high=6.0),
    "QG": StoredSetting("float", 0.0),
    "QI": StoredSetting("float", 1.0),
    "QM": StoredSetting("int", 1.0, high=4.0),  # 1 = DC servo motor
    "QS": StoredSetting("int", 10.0, low=1.0, high=250.0),
    "QT": StoredSetting("float", 0.0, high=20.0),
    "QV": StoredSetting("float", 0.0),
    "SU": StoredSetting("float", 0.0001, low=2e-9, scaled=True),
    "TJ": StoredSetting("int", 1.0, low=1.0, high=6.0),
    "VB": StoredSetting("float", 0.0, high="VU", scaled=True),
    "VF": StoredSetting("float", 0.0),
    "ZA": StoredSetting("hex", 0.0, high=0xFFFF),
    "ZB": StoredSetting("hex", 0.0, high=0xFFFF),
    "ZE": StoredSetting("hex", 0.0, high=0xFFFF),
    "ZF": StoredSetting("hex", 0.0, high=0xFFFF),
    "ZH": StoredSetting("hex", 0.0, high=0xFFFF),
    "ZS": StoredSetting("hex", 0.0, high=0xFFFF),
}
SPEED_SETTINGS = [name for name, spec in STORED_SETTINGS.items() if spec.high == "VU"]


class EmulatedAxis:
    """One ESP axis: its trapezoidal motion plus the controller's per-axis settings."""

    def __init__(self, number: int, clock: VirtualClock, table: Mapping[str, object]):
        unknown = sorted(set(table) - set(AXIS_KEYS))
        if unknown:
            raise EspConfigError(
                f"esp axis {number}: unknown key {unknown[0]!r} (known: {', '.join(AXIS_KEYS)})"
            )
        cfg = {**AXIS_KEYS, **table}
        try:
            lo, hi = (float(v) for v in cfg["limits_deg"])  # type: ignore[union-attr]
            self.motion = TrapezoidAxis(
                clock, float(cfg["speed_deg_s"]), float(cfg["accel_deg_s2"]), (lo, hi),
                float(cfg["position_deg"]),
                None if cfg["decel_deg_s2"] is None else float(cfg["decel_deg_s2"]),
            )
        except (TypeError, ValueError) as exc:
            raise EspConfigError(f"esp axis {number}: {exc}") from None
        self.number = number
        self.max_speed = float(cfg["max_speed_deg_s"])
        self.max_accel = float(cfg["max_accel_deg_s2"])
        if self.motion.speed > self.max_speed or self.motion.accel > self.max_accel:
            raise EspConfigError(f"esp axis {number}: speed/accel above max_speed/max_accel")
        self.motor_on = bool(cfg["motor_on"])
        self.stage_id = str(cfg["stage_id"] or f"ROTARY-EMU, SN{number:04d}")
        self.units = DEGREE
        self.homing = False
        self.home_value = 0.0  # the last DH value, degrees (DH? answers it)
        self.home_preset = 0.0  # SH: where a home search ends, degrees
        self.settings = self._default_settings()

    def _default_settings(self) -> dict[str, float]:
        speed, accel = self.motion.speed, self.motion.accel
        derived = {"AE": self.max_accel, "JH": speed, "JW": speed / 10.0, "JK": 10.0 * accel,
                   "OH": speed, "OL": speed / 10.0}
        return {name: derived.get(name, spec.default) for name, spec in STORED_SETTINGS.items()}

    def fail(self, code: int) -> Fail:
        """This axis's error `code` as the controller numbers it (axis * 100 + code)."""
        return Fail(self.number * 100 + code)

    @property
    def scale(self) -> float:
        """Value in the axis's display units per degree."""
        return ANGULAR_UNITS[self.units]

    def moving(self) -> bool:
        """True while in motion; a finished home search stops counting as homing."""
        moving = self.motion.is_moving()
        if not moving:
            self.homing = False
        return moving

    def home_target(self) -> float:
        """Where a home search ends, degrees: the SH preset if inside the travel, else the
        nearest limit."""
        lo, hi = self.motion.limits
        return min(max(self.home_preset, lo), hi)

    def clamp_speeds(self) -> None:
        """Lower VA and the speed settings bounded by VU to a VU just lowered below them."""
        self.motion.speed = min(self.motion.speed, self.max_speed)
        for name in SPEED_SETTINGS:
            self.settings[name] = min(self.settings[name], self.max_speed)

    def clamp_accels(self) -> None:
        """Lower AC and AG to an AU just lowered below them."""
        self.motion.accel = min(self.motion.accel, self.max_accel)
        self.motion.decel = min(self.motion.decel, self.max_accel)
