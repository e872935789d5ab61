"""A gonio plan as a Bluesky plan: the compiled schedule (gonio.plan.build_schedule) run row
by row under the RunEngine, so its suspenders, pauses and callbacks apply.

Each row starts at a checkpoint (a suspender that fires makes the RunEngine measure the row
again when it resumes), sets the detector's range when it changes, moves the axes whose
target changes (together), settles and dwells as gonio's engine does (the same step,
gonio.row_step), and takes one event in the primary stream: the detector, every axis's
readback and the row's schedule fields (`schedule-index`, `schedule-kind`: sample, dark, beam
or signature; side, point, the plan's angles).
"""

from __future__ import annotations

import itertools
from collections.abc import Generator
from pathlib import Path
from typing import Any

import bluesky.plan_stubs as bps
import bluesky.preprocessors as bpp
import numpy as np
from bluesky.utils import Msg
from ophyd_async.core import AsyncStatus, StandardReadable, soft_signal_r_and_setter
from ophyd_async.plan_stubs import ensure_connected

from gonio.bluesky.ophyd_devices import GonioDevices
from gonio.engine import schedule_tags
from gonio.plan import Plan, build_schedule, load_plan
from gonio.row_step import row_step

PYTHON_TYPES = {"i": int, "f": float, "O": str}  # schedule field kind -> signal datatype


class ScheduleRow(StandardReadable):
    """The schedule fields of the row being measured, read into each event: `set` takes a
    schedule row (the fields named at construction)."""

    def __init__(self, dtype: np.dtype, fields: list[str], name: str = "schedule"):
        self._fields = fields
        self._setters = {}
        with self.add_children_as_readables():
            for field in fields:
                signal, self._setters[field] = soft_signal_r_and_setter(
                    PYTHON_TYPES[dtype[field].kind])
                setattr(self, field, signal)
        super().__init__(name=name)

    @AsyncStatus.wrap
    async def set(self, row: np.void) -> None:
        """Hold this row's fields."""
        for field in self._fields:
            value = row[field]
            self._setters[field](value.item() if isinstance(value, np.generic) else value)


def plan(gonio_plan: str | Path | Plan, devices: GonioDevices, md: dict[str, Any] | None = None
         ) -> Generator[Msg, Any, str]:
    """A Bluesky plan measuring a gonio plan's schedule on `devices` (gonio.bluesky.devices),
    in the schedule's order with its dark, beam and signature readings and ranges; returns the
    run's uid. The plan's own `instrument` is not used: the devices are the instrument."""
    p = gonio_plan if isinstance(gonio_plan, Plan) else load_plan(gonio_plan)
    cfg, inst = devices.config, devices.instrument
    readings = build_schedule(p, cfg).readings
    row_device = ScheduleRow(readings.dtype,
                             ["index", *(name for name, _ in schedule_tags(readings))])
    metadata = {"plan_name": "gonio.bluesky.plan", "gonio_plan": p.name,
                "gonio_plan_path": str(p.path), "instrument_name": cfg.name,
                "num_points": len(readings), "num_intervals": max(len(readings) - 1, 0),
                **({"sample": p.sample.to_json()} if p.sample else {}),  # a dict or nothing
                **(md or {})}
    detectors = [devices.detector, *devices.axes.values(), row_device]

    def rows() -> Generator[Msg, Any, None]:
        yield from ensure_connected(row_device)
        yield from bps.mv(devices.detector.averaging, p.averaging or cfg.detector.averaging)
        range_w, commanded = None, dict.fromkeys(devices.axes)
        for row in readings:
            yield from bps.checkpoint()  # a suspender replays the row from here
            step = row_step(inst, row, commanded, p.dwell_s)
            if step.range_w != range_w:
                range_w = step.range_w
                yield from bps.mv(devices.detector.range_setting, range_w)
            if step.moved:
                yield from bps.mv(*itertools.chain.from_iterable(
                    (devices.axes[role], step.targets[role]) for role in step.moved))
                commanded.update({role: step.targets[role] for role in step.moved})
            pause_s = devices.clock.device_wait_s(step.hold_s)
            if pause_s > 0:
                yield from bps.sleep(pause_s)
            yield from bps.mv(row_device, row)
            yield from bps.trigger_and_read(detectors)

    return (yield from bpp.run_wrapper(rows(), md=metadata))
