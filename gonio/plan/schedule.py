"""`build_schedule` turns a plan into the exact, ordered list of readings the engine runs: every
reading has an index, and the same plan and config always give the same schedule, which is what
makes `--resume` possible. Sample points go in the cheapest order found (as written, or
serpentine over the moving stage axes or the plan's coordinates), with the dark, beam and
signature readings interleaved."""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from gonio.config import InstrumentConfig
from gonio.errors import PlanError
from gonio.fields import location
from gonio.plan.estimate import estimate_seconds, move_times
from gonio.plan.parse import MOTION_ROLES, Plan
from gonio.plan.validate import (
    Ranges,
    check_signature_grid,
    check_sweeps,
    fixed_position,
    resolve_ranges,
    stage_targets,
)

# kind and side are Python strings (object fields): a fixed width would cut a long name.
SCHEDULE_DTYPE = np.dtype([
    ("index", "i8"), ("kind", object), ("side", object), ("repeat", "i4"), ("point", "i8"),
    ("theta_i_deg", "f8"), ("theta_o_deg", "f8"), ("phi_o_deg", "f8"),
    ("sample_deg", "f8"), ("arm_deg", "f8"), ("azimuth_deg", "f8"), ("elevation_deg", "f8"),
    ("range_w", "f8"),
])


@dataclass(frozen=True)
class Schedule:
    """The validated, ordered readings of a plan on an instrument, with time estimates."""

    readings: np.ndarray  # SCHEDULE_DTYPE
    estimate_s: float
    naive_estimate_s: float
    nesting: tuple[str, ...]
    skipped: int  # grid points dropped by skip_forbidden
    time_scale: float | None = None  # the emulated bench's the estimates are for; None: real

    def __len__(self) -> int:
        return len(self.readings)


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


def build_schedule(plan: Plan, cfg: InstrumentConfig, time_scale: float | None = None
                   ) -> Schedule:
    """Validate the plan on the instrument and return its ordered readings and estimates: on
    the real bench, or (time_scale: its [sim] time_scale) on the emulated one."""
    where = str(plan.path) if plan.path else "plan"
    if plan.environment is not None and cfg.environment is not None:
        raise PlanError(f"{location(where, 'environment')}: the instrument's environment sensor "
                        f"{cfg.environment!r} measures the room at every reading; state the "
                        f"environment in one place: remove [environment] from the plan, or the "
                        f"sensor from the config")
    targets, keep = stage_targets(plan, cfg)
    fixed = {k: fixed_position(cfg, k, where) for k, n in
             (("dark", plan.dark_every), ("beam", plan.beam_every),
              ("signature", plan.signature is not None)) if n}
    if plan.signature is not None and plan.signature.arm_deg:
        check_signature_grid(plan, cfg, where)
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
    check_sweeps(readings, where)
    naive_readings = _assemble(_interleave(naive, plan, ranges, targets, fixed), plan)
    scale = 1.0 if time_scale is None else time_scale
    return Schedule(readings, estimate_seconds(readings, cfg, plan, time_scale=scale),
                    estimate_seconds(naive_readings, cfg, plan, time_scale=scale), nesting,
                    int(len(keep) - keep.sum()), time_scale)


def _assemble(items: list[Slot], plan: Plan) -> np.ndarray:
    """The schedule array of the slots; plan angles for sample readings, NaN for the others (a
    signature reading keeps the point it shadows, -1 on a grid of its own)."""
    out = np.zeros(len(items), SCHEDULE_DTYPE)
    out["index"] = np.arange(len(items))
    out["side"] = ""  # a sample reading's side is its point's; no other reading has one
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
