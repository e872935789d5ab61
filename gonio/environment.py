"""The room a run was measured in: the plan's [environment] table (air temperature and relative
humidity with their standard uncertainties, as read off the lab's own sensor).

ASTM E2387 and ISO 19986 ask the record to state the conditions of the measurement; the record
of every run carries this block, and the BiRD export needs the temperature. The values are
entered by hand for the run, or made from an environment sensor's readings when the instrument
has one (gonio.room_sensor; the plan may not state them too).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

from gonio.errors import PlanError
from gonio.fields import Fields, stored_table


@dataclass(frozen=True)
class Environment:
    """[environment]: air temperature in deg C, relative humidity as a fraction (0 to 1), each
    with its standard uncertainty (None when not stated)."""

    temperature_c: float
    u_temperature_c: float | None = None
    humidity_rel: float | None = None
    u_humidity_rel: float | None = None
    notes: str = ""

    def to_json(self) -> dict[str, Any]:
        """The block as stored in the record and exports."""
        return asdict(self)


def parse_environment(f: Fields) -> Environment:
    """Validate an [environment] table: temperature_c is required, an uncertainty needs its
    value."""
    env = Environment(
        temperature_c=f.number("temperature_c", low=-100.0, high=100.0),
        u_temperature_c=f.number("u_temperature_c", None, low=0.0, high=50.0),
        humidity_rel=f.number("humidity_rel", None, low=0.0, high=1.0),
        u_humidity_rel=f.number("u_humidity_rel", None, low=0.0, high=1.0),
        notes=f.string("notes", ""),
    )
    f.done()
    if env.u_humidity_rel is not None and env.humidity_rel is None:
        raise f.fail("u_humidity_rel", "needs humidity_rel (the value it is the uncertainty of)")
    return env


def environment_of_plan(plan: dict[str, Any], where: str = "plan") -> Environment | None:
    """The [environment] of a stored (raw) plan, or None if it has none."""
    return stored_table(plan, "environment", where, PlanError, parse_environment)
