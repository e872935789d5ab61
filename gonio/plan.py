"""Scan plans (TOML): parse, validate against an instrument, order the points, estimate time.

A plan lists sample points (grids and single points of incidence, outgoing angle in and out of
the plane of incidence, reflection/transmission side, sample azimuth) plus repeats, dwell,
averaging and dark/beam readings interleaved at a rate, signature readings (the sample retracted,
the arm where the sample readings go: [signature], interleaved or in one pass), and the detector
range of each reading (`range`: "auto" or a fixed full scale in W; per grid, point, [dark],
[beam] and [signature], else the plan's, else the instrument's [detector] range; a grid may list
several ranges to step through).
`build_schedule` turns it into the exact, ordered list of readings the engine runs: every reading
has an index, and the same plan and config always give the same schedule, which is what makes
`--resume` possible.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import tomllib

from drivers.register_map import RegisterMap
from gonio.config import InstrumentConfig, forbidden_reason
from gonio.errors import PlanError
from gonio.fields import Fields
from gonio.geometry import into_limits, stage_angles
from gonio.sample import SampleInfo, parse_sample
from gonio.suspenders import SuspendSpec, parse_suspend

SIDES = ("reflection", "transmission")
KINDS = ("sample", "dark", "beam", "signature")
SIGNATURE_PASSES = ("interleaved", "after", "prompted")
ORDERS = ("optimal", "as-written")
MOTION_ROLES = ("sample", "arm", "azimuth", "elevation")
AUTO_RANGE = 0.0  # a schedule's range_w when the detector autoranges (else a full scale in W)
UNSET = math.nan  # a plan's range not given at that level: the enclosing level's applies
READ_OVERHEAD_S = 0.02  # estimated protocol time per reading, plus READ_PER_SAMPLE_S each sample
READ_PER_SAMPLE_S = 0.003

POINT_DTYPE = np.dtype([
    ("source", "U24"), ("side", "U12"), ("theta_i_deg", "f8"), ("theta_o_deg", "f8"),
    ("phi_o_deg", "f8"), ("sample_azimuth_deg", "f8"), ("skip_forbidden", "?"),
    ("range_w", "f8"),
])

SCHEDULE_DTYPE = np.dtype([
    ("index", "i8"), ("kind", "U12"), ("side", "U12"), ("repeat", "i4"), ("point", "i8"),
    ("theta_i_deg", "f8"), ("theta_o_deg", "f8"), ("phi_o_deg", "f8"),
    ("sample_deg", "f8"), ("arm_deg", "f8"), ("azimuth_deg", "f8"), ("elevation_deg", "f8"),
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
    signature: SignaturePlan | None = None  # [signature]: instrument-signature readings
    suspend: SuspendSpec | None = None  # [suspend]: conditions that hold the scan (suspenders)


@dataclass(frozen=True)
class Schedule:
    """The validated, ordered readings of a plan on an instrument, with time estimates."""

    readings: np.ndarray  # SCHEDULE_DTYPE
    estimate_s: float
    naive_estimate_s: float
    nesting: tuple[str, ...]
    skipped: int  # grid points dropped by skip_forbidden

    def __len__(self) -> int:
        return len(self.readings)


def load_plan(path: str | Path) -> Plan:
    """Read and parse a plan file (instrument-independent checks only)."""
    path = Path(path)
    try:
        raw = tomllib.loads(path.read_text())
    except OSError as exc:
        raise PlanError(f"{path}: cannot read plan ({exc.strerror})") from None
    except tomllib.TOMLDecodeError as exc:
        raise PlanError(f"{path}: not valid TOML ({exc})") from None
    except UnicodeDecodeError:
        raise PlanError(f"{path}: not a text file") from None
    return parse_plan(raw, path)


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
        signature=_signature(top),
        suspend=parse_suspend(top.table_of("suspend"), beam_every) if top.has("suspend") else None,
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
    f = Fields(table, f"{top.where}: grid[{i}]", PlanError)
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
    f = Fields(table, f"{top.where}: point[{i}]", PlanError)
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


# -- validation against the instrument --------------------------------------------------------

def _describe(p: np.void) -> str:
    return (f"{p['source']} point (side={p['side']}, theta_i={p['theta_i_deg']:g}, "
            f"theta_o={p['theta_o_deg']:g}, phi_o={p['phi_o_deg']:g}, "
            f"sample_azimuth={p['sample_azimuth_deg']:g})")


def stage_targets(plan: Plan, cfg: InstrumentConfig) -> tuple[np.ndarray, np.ndarray]:
    """Stage targets (N, 4) in MOTION_ROLES order for the plan's points, and a keep mask.

    Raises PlanError naming the first point out of travel or in a forbidden zone (unless its
    grid says skip_forbidden, which drops it instead).
    """
    pts = plan.points
    st = stage_angles(pts["theta_i_deg"], pts["theta_o_deg"], pts["phi_o_deg"],
                      pts["side"] == "transmission", pts["sample_azimuth_deg"])
    targets = np.stack([st.sample_deg, st.arm_deg, st.azimuth_deg, st.elevation_deg], axis=1)
    where = str(plan.path) if plan.path else "plan"
    if "arm" in cfg.axes:
        moved = into_limits(targets[:, 1], cfg.axes["arm"].limits_deg)
        targets[:, 1] = np.where(np.isnan(moved), targets[:, 1], moved)
    keep = np.ones(len(pts), bool)
    for k in range(len(pts)):
        reason = forbidden_reason(cfg, targets[k, 1], targets[k, 3])
        if reason is None:
            continue
        if not pts[k]["skip_forbidden"]:
            raise PlanError(f"{where}: {_describe(pts[k])}: {reason} "
                            f"(set skip_forbidden = true in the grid to drop such points)")
        keep[k] = False
    if not keep.any():
        raise PlanError(f"{where}: every point is in a forbidden zone")
    for j, role in enumerate(MOTION_ROLES):
        if role in cfg.axes:
            lo, hi = cfg.axes[role].limits_deg
            bad = keep & ~((targets[:, j] >= lo - 1e-9) & (targets[:, j] <= hi + 1e-9))
            why = f"outside travel [{lo:g}, {hi:g}]"
        else:
            bad = keep & (np.abs(targets[:, j]) > 1e-9)
            why = f"needs a {role!r} axis; the instrument {cfg.name!r} has none"
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise PlanError(f"{where}: {_describe(pts[k])}: {role} at {targets[k, j]:.6g} deg "
                            f"{why}")
        if role not in cfg.axes:
            targets[:, j] = 0.0
    return targets, keep


def _fixed_position(cfg: InstrumentConfig, kind: str, where: str) -> np.ndarray:
    """Stage targets of a dark, beam or signature reading (a signature's arm: NaN, filled in
    per reading), checked against the travel and the forbidden zones."""
    pos = {"beam": cfg.beam, "dark": cfg.dark, "signature": cfg.signature}[kind]
    if pos is None:
        what = "[signature]" if kind == "signature" else f"{kind}.every"
        raise PlanError(f"{where}: {what} asks for {kind} readings but the instrument "
                        f"{cfg.name!r} ({cfg.path or 'config'}) has no [{kind}] position"
                        + (" (add [signature] sample_deg = 90: the sample retracted)"
                           if kind == "signature" else ""))
    for role, value in (("sample", pos.sample_deg), ("arm", pos.arm_deg)):
        lo, hi = cfg.axes[role].limits_deg
        if value is not None and not lo <= value <= hi:
            raise PlanError(f"{where}: the instrument's [{kind}] {role}_deg {value:g} is outside "
                            f"the {role} travel [{lo:g}, {hi:g}]")
    if pos.arm_deg is None:
        return np.array([pos.sample_deg, math.nan, 0.0, 0.0])
    reason = forbidden_reason(cfg, pos.arm_deg)
    if reason:
        raise PlanError(f"{where}: the instrument's [{kind}] position: {reason}")
    return np.array([pos.sample_deg, pos.arm_deg, 0.0, 0.0])


def _signature_grid(plan: Plan, cfg: InstrumentConfig, where: str) -> None:
    """A [signature] arm_deg grid: inside the arm's travel and out of the forbidden zones."""
    lo, hi = cfg.axes["arm"].limits_deg
    for arm in plan.signature.arm_deg:
        reason = (None if lo - 1e-9 <= arm <= hi + 1e-9 else
                  f"outside the arm travel [{lo:g}, {hi:g}]") or forbidden_reason(cfg, arm)
        if reason:
            raise PlanError(f"{where}: [signature] arm_deg {arm:g}: {reason}")


# -- ordering and estimates -------------------------------------------------------------------

def profile_seconds(distance: Any, speed: float, accel: float) -> np.ndarray:
    """Rest-to-rest trapezoidal move time: v/a + d/v if d >= v^2/a, else 2 sqrt(d/a)."""
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


def serpentine(values: np.ndarray, nesting: tuple[int, ...]) -> np.ndarray:
    """Order of rows of `values` (N, k): sorted by columns in `nesting` order, outer first,
    each inner level alternating direction (boustrophedon) within its enclosing group."""
    group = np.zeros(len(values), np.int64)
    for col in nesting:
        _, rank = np.unique(values[:, col], return_inverse=True)
        rank = rank.ravel().astype(np.int64)
        top = int(rank.max()) + 1
        key = np.where(group % 2 == 0, rank, top - 1 - rank)
        _, group = np.unique(group * top + key, return_inverse=True)
        group = group.ravel().astype(np.int64)
    return np.argsort(group, kind="stable")


PLAN_COORDS = ("sample_azimuth_deg", "side", "theta_i_deg", "phi_o_deg", "theta_o_deg")


def _best_order(points: np.ndarray, targets: np.ndarray, cfg: InstrumentConfig
                ) -> tuple[np.ndarray, tuple[str, ...]]:
    """The cheapest of: the order as written, and serpentine orders over every nesting of the
    moving stage axes and of the varying plan coordinates. Returns (order, nesting names)."""
    coords = np.stack([points["side"] == "transmission" if c == "side" else points[c]
                       for c in PLAN_COORDS], axis=1).astype(np.float64)
    candidates: list[tuple[np.ndarray, tuple[str, ...]]] = [(np.arange(len(points)), ())]
    for values, names in ((targets, MOTION_ROLES), (coords, PLAN_COORDS)):
        varying = [j for j in range(values.shape[1]) if np.ptp(values[:, j]) > 0]
        for nesting in itertools.permutations(varying):
            candidates.append((serpentine(values, nesting), tuple(names[j] for j in nesting)))
    costs = [float(move_times(targets[order], cfg).sum()) for order, _ in candidates]
    return candidates[int(np.argmin(costs))]


Slot = tuple[str, int, int, float, np.ndarray]  # kind, repeat, point, range_w, stage targets


def _interleave(passes: list[tuple[int, np.ndarray]], plan: Plan, ranges: Ranges,
                targets: np.ndarray, fixed: dict[str, np.ndarray]) -> list[Slot]:
    """Every reading in order: sample points with dark/beam ones interleaved (a dark slot holds
    one dark reading per range of ranges.dark) and signature ones: right after every N-th
    sample reading, at its arm, elevation and azimuth; or in one pass after the last sample
    reading, before a closing dark and beam reading."""
    out: list[Slot] = []
    sig = plan.signature
    extras = [(k, n) for k, n in (("dark", plan.dark_every), ("beam", plan.beam_every)) if n]

    def extra(kind: str, repeat: int) -> None:
        for r in (ranges.dark if kind == "dark" else (ranges.beam,)):
            out.append((kind, repeat, -1, r, fixed[kind]))

    def shadow(repeat: int, k: int) -> Slot:
        """The signature reading of sample point k: the sample retracted, the rest as k's."""
        range_w = ranges.sample[k] if math.isnan(ranges.signature) else ranges.signature
        pos = np.concatenate([fixed["signature"][:1], targets[k][1:]])
        return "signature", repeat, k, float(range_w), pos

    for kind, _ in extras:
        extra(kind, 0)
    done = 0
    for repeat, order in passes:
        for k in order:
            out.append(("sample", repeat, int(k), float(ranges.sample[k]), targets[k]))
            done += 1
            if sig is not None and sig.every and done % sig.every == 0:
                out.append(shadow(repeat, int(k)))
            for kind, every in extras:
                if done % every == 0:
                    extra(kind, repeat)
    last_repeat = passes[-1][0]
    one_pass = sig is not None and not sig.every
    if one_pass and sig.arm_deg:
        for arm in sig.arm_deg:
            pos = fixed["signature"].copy()
            pos[1] = arm
            out.append(("signature", last_repeat, -1, ranges.signature, pos))
    elif one_pass:  # each distinct position (and range) of the last pass's sample readings
        seen: set[tuple[float, ...]] = set()
        for k in passes[-1][1]:
            key = (*targets[k][1:], ranges.sample[k])
            if key not in seen:
                seen.add(key)
                out.append(shadow(last_repeat, int(k)))
    for kind, every in extras:
        if done % every or one_pass:
            extra(kind, last_repeat)
    return out


@dataclass(frozen=True)
class Ranges:
    """The detector range (AUTO_RANGE or a full scale in W) of each kind of reading."""

    sample: np.ndarray  # per plan point
    dark: tuple[float, ...]  # one dark reading per range in each dark slot
    beam: float
    signature: float = UNSET  # UNSET: the range of the sample reading a signature one shadows


def resolve_ranges(plan: Plan, cfg: InstrumentConfig, keep: np.ndarray) -> Ranges:
    """Each reading's range: its grid's or point's, else the plan's, else the instrument's
    [detector] range; beam readings their [beam] range, else the same fallbacks; dark readings
    their [dark] range, else one on each range the (kept) sample points use; signature readings
    their [signature] range, else the sample reading's (an arm_deg grid: the plan's). Checked
    against the ranges a Modbus detector's register map lists (a PM100's sensor: when the run
    starts)."""
    base = plan.range_w
    if math.isnan(base):
        base = AUTO_RANGE if cfg.detector.range_w is None else cfg.detector.range_w
    sample = np.where(np.isnan(plan.points["range_w"]), base, plan.points["range_w"])
    beam = base if math.isnan(plan.beam_range_w) else plan.beam_range_w
    dark = (tuple(sorted({float(r) for r in sample[keep]})) if math.isnan(plan.dark_range_w)
            else (plan.dark_range_w,))
    sig = plan.signature
    signature = UNSET if sig is None else (
        sig.range_w if not math.isnan(sig.range_w) else base if sig.arm_deg else UNSET)
    where = str(plan.path) if plan.path else "plan"
    largest = detector_largest_range(cfg)
    if largest is not None:
        named = [(f"{p['source']} point", r) for p, r in zip(plan.points[keep], sample[keep],
                                                              strict=True)]
        named += [("[dark]", r) for r in dark] + [("[beam]", beam)]
        named += [("[signature]", signature)] if not math.isnan(signature) else []
        for what, r in named:
            if r > largest * (1.0 + 1e-9):
                raise PlanError(f"{where}: {what}: range {r:g} W is above the largest range "
                                f"{largest:g} W of the detector {cfg.detector.device!r}")
    return Ranges(sample, dark, beam, signature)


def detector_largest_range(cfg: InstrumentConfig) -> float | None:
    """The largest full scale the instrument's detector offers, if the config knows it (a
    Modbus amplifier's register map lists its gain ranges), else None."""
    device = cfg.devices[cfg.detector.device]
    if not device.register_map:
        return None
    ranges = RegisterMap.load(device.register_map).gain_ranges_w
    return max(ranges) if ranges else None


def build_schedule(plan: Plan, cfg: InstrumentConfig) -> Schedule:
    """Validate the plan on the instrument and return its ordered readings and estimates."""
    where = str(plan.path) if plan.path else "plan"
    targets, keep = stage_targets(plan, cfg)
    fixed = {k: _fixed_position(cfg, k, where) for k, n in
             (("dark", plan.dark_every), ("beam", plan.beam_every),
              ("signature", plan.signature is not None)) if n}
    if plan.signature is not None and plan.signature.arm_deg:
        _signature_grid(plan, cfg, where)
    ranges = resolve_ranges(plan, cfg, keep)
    kept = np.flatnonzero(keep)
    naive = [(r, kept) for r in range(plan.repeats)]
    if plan.order == "optimal":
        order, nesting = _best_order(plan.points[kept], targets[kept], cfg)
        order = kept[order]
        passes = [(r, order if r % 2 == 0 else order[::-1]) for r in range(plan.repeats)]
    else:
        passes, nesting = naive, ()
    readings = _assemble(_interleave(passes, plan, ranges, targets, fixed), plan)
    _check_sweeps(readings, where)
    naive_readings = _assemble(_interleave(naive, plan, ranges, targets, fixed), plan)
    return Schedule(readings, estimate_seconds(readings, cfg, plan),
                    estimate_seconds(naive_readings, cfg, plan), nesting,
                    int(len(keep) - keep.sum()))


def sweeps_source(start_deg: Any, end_deg: Any) -> np.ndarray:
    """True where an arm move from start to end passes the source (arm = 0 mod 360)."""
    lo, hi = np.minimum(start_deg, end_deg), np.maximum(start_deg, end_deg)
    return np.ceil(np.asarray(lo) / 360.0) <= np.floor(np.asarray(hi) / 360.0)


def _check_sweeps(readings: np.ndarray, where: str) -> None:
    """No arm move may sweep through the source on its way."""
    arm = readings["arm_deg"]
    crossing = sweeps_source(arm[:-1], arm[1:])
    if crossing.any():
        k = int(np.flatnonzero(crossing)[0])
        raise PlanError(f"{where}: between readings {k} and {k + 1} the arm would sweep through "
                        f"the source ({arm[k]:g} -> {arm[k + 1]:g} deg); give the arm travel "
                        f"limits that exclude 0, e.g. limits_deg = [6, 354]")


def _assemble(items: list[Slot], plan: Plan) -> np.ndarray:
    """The schedule array of the slots; plan angles for sample readings, NaN for the others (a
    signature reading keeps the point it shadows, -1 on a grid of its own)."""
    out = np.zeros(len(items), SCHEDULE_DTYPE)
    out["index"] = np.arange(len(items))
    pos = np.empty((len(items), 4))
    for i, (kind, repeat, k, range_w, target) in enumerate(items):
        out[i]["kind"], out[i]["repeat"], out[i]["point"] = kind, repeat, k
        out[i]["range_w"] = range_w
        pos[i] = target
        if kind == "sample":
            p = plan.points[k]
            out[i]["side"] = p["side"]
            out[i]["theta_i_deg"], out[i]["theta_o_deg"] = p["theta_i_deg"], p["theta_o_deg"]
            out[i]["phi_o_deg"] = p["phi_o_deg"]
        else:
            out[i]["theta_i_deg"] = out[i]["theta_o_deg"] = out[i]["phi_o_deg"] = math.nan
    for j, role in enumerate(MOTION_ROLES):
        out[f"{role}_deg"] = pos[:, j]
    return out


def positions(readings: np.ndarray) -> np.ndarray:
    """Stage targets (N, 4) of scheduled readings, in MOTION_ROLES order."""
    return np.stack([readings[f"{r}_deg"] for r in MOTION_ROLES], axis=1)


def estimate_seconds(readings: np.ndarray, cfg: InstrumentConfig, plan: Plan,
                     start: np.ndarray | None = None) -> float:
    """Estimated run time: motion profiles (axes together) + settle + dwell + read time."""
    if len(readings) == 0:
        return 0.0
    averaging = plan.averaging or cfg.detector.averaging
    per_read = plan.dwell_s + READ_OVERHEAD_S + READ_PER_SAMPLE_S * averaging
    return float(move_times(positions(readings), cfg, start).sum() + per_read * len(readings))


def summary(plan: Plan, cfg: InstrumentConfig, sched: Schedule) -> str:
    """Human summary: what is measured, how many readings, and the time estimates."""
    r = sched.readings
    kinds = {k: int((r["kind"] == k).sum()) for k in KINDS}
    samples = r[r["kind"] == "sample"]
    lines = [
        f"plan {plan.name!r} on instrument {cfg.name!r}",
        f"  sample points: {len(plan.points) - sched.skipped} x {plan.repeats} repeat(s)"
        + (f" ({sched.skipped} in forbidden zones skipped)" if sched.skipped else ""),
        f"  readings: {len(r)} ({kinds['sample']} sample, {kinds['dark']} dark, "
        f"{kinds['beam']} beam" + (f", {kinds['signature']} signature" if kinds["signature"]
                                   else "") + ")",
    ]
    if plan.signature is not None:
        lines.append(f"  signature: {describe_signature(plan.signature)}")
    for side in SIDES:
        s = samples[samples["side"] == side]
        if len(s):
            lines.append(
                f"  {side}: theta_i {_span(s['theta_i_deg'])}, theta_o {_span(s['theta_o_deg'])},"
                f" phi_o {_span(s['phi_o_deg'])} deg")
    lines += [
        f"  detector range: {describe_ranges(r['range_w'])}",
        f"  dwell {plan.dwell_s:g} s, averaging {plan.averaging or cfg.detector.averaging}, "
        f"order {plan.order}" + (f" (nesting {' > '.join(sched.nesting)})" if sched.nesting
                                 else ""),
        f"  estimated duration: {format_duration(sched.estimate_s)}"
        f" (as written: {format_duration(sched.naive_estimate_s)})",
    ]
    return "\n".join(lines)


def describe_signature(sig: SignaturePlan) -> str:
    """How a plan takes its signature readings, in words."""
    if sig.every:
        return (f"the sample retracted after every {sig.every} sample reading(s), at its arm "
                "position")
    where = (f"{len(sig.arm_deg)} arm positions of its own" if sig.arm_deg
             else "each sample reading's arm position")
    prompt = (": the scan waits for the operator to remove the sample first"
              if sig.mode == "prompted" else "")
    return f"one pass after the sample readings, the sample retracted, at {where}{prompt}"


def describe_range(range_w: float) -> str:
    """A schedule's range as text: "auto" or the full scale in W."""
    return "auto" if range_w == AUTO_RANGE else f"{range_w:g} W"


def describe_ranges(ranges_w: np.ndarray) -> str:
    """The distinct ranges of some readings, e.g. "auto" or "1e-07 W, 1e-06 W"."""
    return ", ".join(describe_range(float(r)) for r in np.unique(ranges_w))


def listing(sched: Schedule) -> str:
    """Every scheduled reading, one line each: what it measures and where the stages go."""
    head = (f"{'index':>6} {'kind':<9} {'side':<12} {'rep':>3} {'theta_i':>8} {'theta_o':>8} "
            f"{'phi_o':>7}  {'sample':>8} {'arm':>8} {'azimuth':>8} {'elev':>7} {'range':>9}")
    lines = [head]
    for r in sched.readings:
        lines.append(f"{r['index']:>6} {r['kind']:<9} {r['side']:<12} {r['repeat']:>3} "
                     f"{r['theta_i_deg']:>8.3f} {r['theta_o_deg']:>8.3f} {r['phi_o_deg']:>7.2f}  "
                     f"{r['sample_deg']:>8.3f} {r['arm_deg']:>8.3f} {r['azimuth_deg']:>8.3f} "
                     f"{r['elevation_deg']:>7.3f} {describe_range(r['range_w']):>9}")
    return "\n".join(lines)


def _span(values: np.ndarray) -> str:
    u = np.unique(values)
    return f"{u[0]:g}" if len(u) == 1 else f"{u[0]:g}..{u[-1]:g} ({len(u)} values)"


def format_duration(seconds: float) -> str:
    """Seconds as h:mm:ss (and the raw seconds when short)."""
    s = int(round(seconds))
    text = f"{s // 3600}:{s % 3600 // 60:02d}:{s % 60:02d}"
    return f"{text} ({seconds:.1f} s)" if seconds < 600 else text
