"""A plan checked against an instrument: every stage target inside travel and out of the
forbidden zones, the fixed (dark, beam, signature) positions, each reading's detector range,
and no arm move through the source."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from gonio.config import InstrumentConfig, forbidden_reason
from gonio.errors import PlanError
from gonio.fields import location
from gonio.geometry import into_limits, stage_angles
from gonio.plan.parse import AUTO_RANGE, MOTION_ROLES, UNSET, Plan


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


def fixed_position(cfg: InstrumentConfig, kind: str, where: str) -> np.ndarray:
    """Stage targets of a dark, beam or signature reading (a signature's arm: NaN, filled in
    per reading), checked against the travel and the forbidden zones."""
    pos = {"beam": cfg.beam, "dark": cfg.dark, "signature": cfg.signature}[kind]
    if pos is None:
        what = location(where, kind, "" if kind == "signature" else "every")
        raise PlanError(f"{what}: asks for {kind} readings but the instrument "
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


def check_signature_grid(plan: Plan, cfg: InstrumentConfig, where: str) -> None:
    """A [signature] arm_deg grid: inside the arm's travel and out of the forbidden zones."""
    lo, hi = cfg.axes["arm"].limits_deg
    for arm in plan.signature.arm_deg:
        reason = (None if lo - 1e-9 <= arm <= hi + 1e-9 else
                  f"outside the arm travel [{lo:g}, {hi:g}]") or forbidden_reason(cfg, arm)
        if reason:
            raise PlanError(f"{where}: [signature] arm_deg {arm:g}: {reason}")


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
    """The largest full scale the instrument's detector offers, if its kind knows it from the
    config (a Modbus amplifier's register map lists its gain ranges), else None."""
    device = cfg.devices[cfg.detector.device]
    known = device.kind.config_full_scales_w
    ranges = known(device) if known is not None else ()
    return max(ranges) if ranges else None


def sweeps_source(start_deg: Any, end_deg: Any) -> np.ndarray | bool:
    """True where an arm move from start to end passes the source (arm = 0 mod 360); a bool
    for two numbers (the engine's check of each move)."""
    if isinstance(start_deg, float | int) and isinstance(end_deg, float | int):
        if not (math.isfinite(start_deg) and math.isfinite(end_deg)):  # as the array route
            return bool(sweeps_source(np.array([start_deg]), np.array([end_deg]))[0])
        lo, hi = sorted((start_deg, end_deg))
        return math.ceil(lo / 360.0) <= math.floor(hi / 360.0)
    lo, hi = np.minimum(start_deg, end_deg), np.maximum(start_deg, end_deg)
    return np.ceil(np.asarray(lo) / 360.0) <= np.floor(np.asarray(hi) / 360.0)


def check_sweeps(readings: np.ndarray, where: str) -> None:
    """No arm move may sweep through the source on its way."""
    arm = readings["arm_deg"]
    crossing = sweeps_source(arm[:-1], arm[1:])
    if crossing.any():
        k = int(np.flatnonzero(crossing)[0])
        raise PlanError(f"{where}: between readings {k} and {k + 1} the arm would sweep through "
                        f"the source ({arm[k]:g} -> {arm[k + 1]:g} deg); give the arm travel "
                        f"limits that exclude 0, e.g. limits_deg = [6, 354]")
