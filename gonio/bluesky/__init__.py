"""gonio under Bluesky (the `bluesky` extra): `devices(CONFIG, sim=False)` opens a config's
axes and detector as ophyd-async devices, `plan(PLAN, devices)` runs a gonio plan's schedule
as a Bluesky plan. docs/ecosystem.md."""

from gonio.bluesky.ophyd_devices import (
    DeviceFailure,
    GonioAxis,
    GonioDetector,
    GonioDevices,
    RangeSetting,
    devices,
)
from gonio.bluesky.schedule_plan import ScheduleRow, plan

__all__ = ["DeviceFailure", "GonioAxis", "GonioDetector", "GonioDevices", "RangeSetting",
           "ScheduleRow", "devices", "plan"]
