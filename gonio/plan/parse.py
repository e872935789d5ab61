"""Scan plans (TOML) parsed into a `Plan`: its sample points as written, and how to run them.

A plan lists sample points (grids and single points of incidence, outgoing angle in and out of
the plane of incidence, reflection/transmission side, sample azimuth) plus repeats, dwell,
averaging and dark/beam readings interleaved at a rate, signature readings (the sample retracted,
the arm where the sample readings go: [signature], interleaved or in one pass), and the detector
range of each reading (`range`: "auto" or a fixed full scale in W; per grid, point, [dark],
[beam] and [signature], else the plan's, else the instrument's [detector] range; a grid may list
several ranges to step through). Only instrument-independent checks happen here.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gonio.environment import Environment, parse_environment
from gonio.errors import PlanError
from gonio.fields import Fields, read_toml
from gonio.invalid_readings import DEFAULT_MAX_INVALID_SHARE
from gonio.sample import SampleInfo, parse_sample
from gonio.suspenders import SuspendSpec, parse_suspend

SIDES = ("reflection", "transmission")
KINDS = ("sample", "dark", "beam", "signature")
SIGNATURE_PASSES = ("interleaved", "after", "prompted")
ORDERS = ("optimal", "as-written")
#: What a calibration plan measures (its `calibrates`, recorded in the run); none: a BSDF.
CALIBRATES = ("detector", "aperture", "angles")
MOTION_ROLES = ("sample", "arm", "azimuth", "elevation")
AUTO_RANGE = 0.0  # a schedule's range_w when the detector autoranges (else a full scale in W)
UNSET = math.nan  # a plan's range not given at that level: the enclosing level's applies

# Names (source, side) are Python strings (object fields): a fixed width would cut a long one.
POINT_DTYPE = np.dtype([
    ("source", object), ("side", object), ("theta_i_deg", "f8"), ("theta_o_deg", "f8"),
    ("phi_o_deg", "f8"), ("sample_azimuth_deg", "f8"), ("skip_forbidden", "?"),
    ("range_w", "f8"),
])


@dataclass(frozen=True)
class SignaturePlan:
    """[signature]: readings with the sample retracted ([signature] position of the instrument)
    that measure what the bench adds to a sample reading at the same arm position."""

    every: int  # interleaved: one after every N-th sample reading, at its position; else 0
    mode: str  # "interleaved" | "after" (one pass after the sample readings) | "prompted"
    arm_deg: tuple[float, ...] = ()  # a pass's own arm positions; (): the sample readings'
    range_w: float = UNSET  # UNSET: the range of the sample reading it shadows (own grid: plan's)


@dataclass(frozen=True)
class Plan:
    """A parsed plan: sample points as written plus how to run them."""

    name: str
    path: Path | None
    instrument: Path | None
    points: np.ndarray  # POINT_DTYPE, in the order written
    repeats: int
    dwell_s: float
    averaging: int | None
    order: str
    dark_every: int
    beam_every: int
    description: str = ""
    raw: dict[str, Any] = field(default_factory=dict, repr=False)
    range_w: float = UNSET  # the plan's detector range (AUTO_RANGE, a full scale in W, UNSET)
    dark_range_w: float = UNSET  # UNSET: a dark reading on every range the samples use
    beam_range_w: float = UNSET  # UNSET: the plan's range
    sample: SampleInfo | None = None  # [sample]: what is measured
    environment: Environment | None = None  # [environment]: the room's temperature, humidity
    signature: SignaturePlan | None = None  # [signature]: instrument-signature readings
    calibrates: str | None = None  # one of CALIBRATES for a calibration run; None: a BSDF
    suspend: SuspendSpec | None = None  # [suspend]: conditions that hold the scan (suspenders)
    # the share of the planned readings that may be invalid before the run fails
    max_invalid_share: float = DEFAULT_MAX_INVALID_SHARE


def load_plan(path: str | Path) -> Plan:
    """Read and parse a plan file (instrument-independent checks only)."""
    path = Path(path)
    return parse_plan(read_toml(path, "plan", PlanError), path)


def parse_plan(raw: dict[str, Any], path: str | Path | None = None) -> Plan:
    """Parse a plan dict; `instrument` resolves relative to the plan file's folder."""
    path = Path(path) if path is not None else None
    top = Fields(raw, str(path) if path else "plan", PlanError)
    name = top.string("name", default=path.stem if path else "plan")
    instrument = top.string("instrument", default=None)
    if instrument is not None:
        instrument = ((path.parent if path else Path.cwd()) / instrument).resolve()
    points = [_grid(top, i, g) for i, g in enumerate(_tables(top, "grid"))]
    points += [_single(top, i, p) for i, p in enumerate(_tables(top, "point"))]
    if not points:
        raise PlanError(f"{top.where}: no points; add a [[grid]] or a [[point]] table")
    dark_every, dark_range = _every(top, "dark")
    beam_every, beam_range = _every(top, "beam")
    plan = Plan(
        name=name, path=path, instrument=instrument,
        points=np.concatenate(points),
        repeats=top.number("repeats", 1, low=1, high=10_000, integer=True),
        dwell_s=top.number("dwell_s", 0.0, low=0.0, high=3600.0),
        averaging=top.number("averaging", None, low=1, high=100_000, integer=True),
        order=top.string("order", "optimal", choices=ORDERS),
        dark_every=dark_every,
        beam_every=beam_every,
        description=top.string("description", ""),
        raw=raw,
        range_w=_ranges(top)[0],
        dark_range_w=dark_range,
        beam_range_w=beam_range,
        sample=parse_sample(top.table_of("sample")) if top.has("sample") else None,
        environment=(parse_environment(top.table_of("environment"))
                     if top.has("environment") else None),
        signature=_signature(top),
        calibrates=top.string("calibrates", None, choices=CALIBRATES),
        suspend=parse_suspend(top.table_of("suspend"), beam_every) if top.has("suspend") else None,
        max_invalid_share=top.number("max_invalid_share", DEFAULT_MAX_INVALID_SHARE, low=0.0,
                                     high=1.0),
    )
    top.done()
    return plan


def _tables(top: Fields, key: str) -> list[Any]:
    value = top._get(key, [])
    if isinstance(value, dict):
        return [value]
    if not isinstance(value, list):
        raise top.fail(key, f"must be a table or an array of tables [[{key}]]")
    return value


def _ranges(f: Fields, several: bool = False) -> tuple[float, ...]:
    """The table's detector range(s): AUTO_RANGE for "auto", a full scale in W, UNSET if absent;
    a grid (several) may list several, which it steps through at each of its points."""
    value = f._get("range", None)
    if value is None:
        return (UNSET,)
    values = value if several and isinstance(value, list) and value else [value]
    out = []
    for v in values:
        if v == "auto":
            out.append(AUTO_RANGE)
        elif (isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
              and v > 0):
            out.append(float(v))
        else:
            lists = " or a list of them" if several else ""
            raise f.fail("range", f'must be "auto" or a fixed full scale in W > 0{lists}; '
                                  f"got {v!r}")
    return tuple(dict.fromkeys(out))


def _sides(f: Fields) -> tuple[str, ...]:
    value = f._get("side", "reflection")
    values = value if isinstance(value, list) else [value]
    if not values or any(v not in SIDES for v in values):
        raise f.fail("side", "must be 'reflection', 'transmission' or a list of them; "
                             f"got {value!r}")
    return tuple(dict.fromkeys(values))


def _grid(top: Fields, i: int, table: Any) -> np.ndarray:
    f = Fields(table, top.source, PlanError, f"grid[{i}]")
    sides = _sides(f)
    ti = f.values("theta_i_deg", low=-90.0, high=90.0)
    to = f.values("theta_o_deg", low=-90.0, high=90.0)
    po = f.values("phi_o_deg", (0.0,), low=-180.0, high=180.0)
    az = f.values("sample_azimuth_deg", (0.0,), low=-360.0, high=360.0)
    skip = f.boolean("skip_forbidden", False)
    ranges = _ranges(f, several=True)
    f.done()
    combos = list(itertools.product(sides, az, ti, po, to, ranges))
    if len(combos) > 1_000_000:
        raise PlanError(f"{f.where}: {len(combos)} points; at most 1000000 per grid")
    out = np.zeros(len(combos), POINT_DTYPE)
    out["source"] = f"grid[{i}]"
    out["side"] = [c[0] for c in combos]
    out["sample_azimuth_deg"] = [c[1] for c in combos]
    out["theta_i_deg"] = [c[2] for c in combos]
    out["phi_o_deg"] = [c[3] for c in combos]
    out["theta_o_deg"] = [c[4] for c in combos]
    out["range_w"] = [c[5] for c in combos]
    out["skip_forbidden"] = skip
    return out


def _single(top: Fields, i: int, table: Any) -> np.ndarray:
    f = Fields(table, top.source, PlanError, f"point[{i}]")
    side = f.string("side", "reflection", choices=SIDES)
    out = np.zeros(1, POINT_DTYPE)
    out[0] = (f"point[{i}]", side, f.number("theta_i_deg", low=-90.0, high=90.0),
              f.number("theta_o_deg", low=-90.0, high=90.0),
              f.number("phi_o_deg", 0.0, low=-180.0, high=180.0),
              f.number("sample_azimuth_deg", 0.0, low=-360.0, high=360.0), False,
              _ranges(f)[0])
    f.done()
    return out


def _every(top: Fields, key: str) -> tuple[int, float]:
    """[dark] or [beam]: one such reading every N sample readings, and its detector range."""
    if not top.has(key):
        return 0, UNSET
    f = top.table_of(key)
    every = f.number("every", low=0, high=1_000_000, integer=True)
    range_w = _ranges(f)[0]
    f.done()
    return every, range_w


def _signature(top: Fields) -> SignaturePlan | None:
    """[signature]: `every = N` (interleaved), or one pass (`pass = "after"`, the default
    without `every`, or "prompted") at its own `arm_deg` or the sample readings' positions."""
    if not top.has("signature"):
        return None
    f = top.table_of("signature")
    every = f.number("every", 0, low=1, high=1_000_000, integer=True)
    mode = f.string("pass", "interleaved" if every else "after", choices=SIGNATURE_PASSES)
    arm = f.values("arm_deg", (), low=-360.0, high=360.0)
    range_w = _ranges(f)[0]
    f.done()
    if mode == "interleaved" and not every:
        raise f.fail("pass", '"interleaved" needs every = N (a signature reading after every '
                             "N-th sample reading)")
    if every and mode != "interleaved":
        raise f.fail("every", f'interleaves the signature readings; pass = "{mode}" takes them '
                              "in one pass after the sample readings: give one of the two")
    if every and arm:
        raise f.fail("arm_deg", 'a grid of its own is measured in one pass (pass = "after" or '
                                '"prompted"); every = N reads at each sample reading\'s arm')
    return SignaturePlan(every, mode, arm, range_w)
