"""How long a schedule takes: trapezoidal moves (the axes together, the slowest sets the time),
settling, dwell and the detector's read time."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from gonio.config import InstrumentConfig
from gonio.plan.parse import MOTION_ROLES, Plan

READ_OVERHEAD_S = 0.02  # estimated protocol time per reading, plus READ_PER_SAMPLE_S each sample
READ_PER_SAMPLE_S = 0.003


def profile_seconds(distance: Any, speed: float, accel: float) -> np.ndarray | float:
    """Rest-to-rest trapezoidal move time: v/a + d/v if d >= v^2/a, else 2 sqrt(d/a) (a number
    for a number: the engine asks once per move)."""
    if isinstance(distance, float | int):
        d = abs(float(distance))
        return speed / accel + d / speed if d * accel >= speed * speed else 2.0 * math.sqrt(
            d / accel)
    d = np.abs(np.asarray(distance, dtype=np.float64))
    return np.where(d * accel >= speed * speed, speed / accel + d / speed,
                    2.0 * np.sqrt(d / accel))


def move_times(targets: np.ndarray, cfg: InstrumentConfig, start: np.ndarray | None = None
               ) -> np.ndarray:
    """Seconds of each move (axes together: the slowest sets it) plus settling, from `start`."""
    targets = np.asarray(targets, dtype=np.float64)
    start = targets[:1] if start is None else np.asarray(start, dtype=np.float64)[None]
    delta = np.abs(np.diff(np.concatenate([start, targets]), axis=0))
    total = np.zeros(len(targets))
    settle = np.zeros(len(targets))
    for j, role in enumerate(MOTION_ROLES):
        if role not in cfg.axes:
            continue
        ax = cfg.axes[role]
        total = np.maximum(total, profile_seconds(delta[:, j], ax.speed_deg_s, ax.accel_deg_s2))
        settle = np.maximum(settle, np.where(delta[:, j] > 0, ax.settle_s, 0.0))
    return total + settle


def positions(readings: np.ndarray) -> np.ndarray:
    """Stage targets (N, 4) of scheduled readings, in MOTION_ROLES order."""
    return np.stack([readings[f"{r}_deg"] for r in MOTION_ROLES], axis=1)


def estimate_seconds(readings: np.ndarray, cfg: InstrumentConfig, plan: Plan,
                     start: np.ndarray | None = None, time_scale: float = 1.0) -> float:
    """Estimated run time: motion profiles (axes together) + settle + dwell, which an emulated
    bench runs time_scale times faster (its virtual seconds per real second; inf: at once, as
    the engine waits), + read time."""
    if len(readings) == 0:
        return 0.0
    averaging = plan.averaging or cfg.detector.averaging
    device_s = move_times(positions(readings), cfg, start).sum() + plan.dwell_s * len(readings)
    read_s = (READ_OVERHEAD_S + READ_PER_SAMPLE_S * averaging) * len(readings)
    return float((0.0 if math.isinf(time_scale) else device_s / time_scale) + read_s)
