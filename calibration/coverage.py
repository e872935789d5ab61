"""Does a calibration cover a plan? Every detector range the plan's readings can fall on needs
a dark offset and a gain in the calibration file, checked before any motion (`gonio scan
--calibration`) once the detector is open, since a PM100's ranges come from its sensor.

A fixed-range reading falls on the detector's smallest range holding that full scale; an
autoranged one on any range from the detector's smallest up to the beam readings' range (the
brightest light the plan sees), which is the detector's largest when the beam autoranges too
or the plan takes no beam readings.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from calibration.calfile import Calibration
from calibration.detector import range_key
from calibration.values import CalibrationError
from gonio.plan import AUTO_RANGE


def device_range(range_w: float, full_scales_w: Sequence[float]) -> float:
    """The detector range a fixed setting selects: the smallest full scale holding it (the
    largest if none does)."""
    return next((fs for fs in full_scales_w if range_w <= fs * (1 + 1e-9)), full_scales_w[-1])


def ranges_read(schedule: np.ndarray, full_scales_w: Sequence[float]) -> list[float]:
    """The detector ranges (full scale, W, increasing) a schedule's readings can fall on (the
    module's rule); full_scales_w: the detector's ranges, increasing."""
    settings = schedule["range_w"]
    out = {device_range(float(r), full_scales_w) for r in settings if r != AUTO_RANGE}
    if np.any(settings == AUTO_RANGE):
        beam = schedule["range_w"][schedule["kind"] == "beam"]
        top = (max(device_range(float(r), full_scales_w) for r in beam)
               if len(beam) and np.all(beam != AUTO_RANGE) else full_scales_w[-1])
        out.update(fs for fs in full_scales_w if fs <= top)
    return sorted(out)


def uncovered(cal: Calibration, ranges_w: Sequence[float]) -> dict[str, list[str]]:
    """Per range key the calibration lacks something for: what it lacks ("dark offset",
    "gain")."""
    out = {}
    for r in ranges_w:
        key = range_key(r)
        lacking = [what for what, table in (("dark offset", cal.dark_offsets_w),
                                            ("gain", cal.gains)) if key not in (table or {})]
        if lacking:
            out[key] = lacking
    return out


def require(cal: Calibration, where: str, schedule: np.ndarray,
            full_scales_w: Sequence[float]) -> None:
    """CalibrationError (one line naming the missing ranges) unless the calibration `where`
    covers every range the schedule can read on."""
    needed = ranges_read(schedule, full_scales_w)
    missing = uncovered(cal, needed)
    if missing:
        listed = ", ".join(f"{key} W ({', '.join(what)})" for key, what in missing.items())
        raise CalibrationError(
            f"calibration {where} does not cover the detector ranges the plan can read on "
            f"({range_key(needed[0])}..{range_key(needed[-1])} W): it lacks {listed}; add them "
            "to the detector calibration run (examples/plans/calib-detector.toml) or fix the "
            "plan's ranges")
