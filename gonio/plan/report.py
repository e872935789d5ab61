"""A plan and its schedule in words: the summary `gonio plan` prints, the listing of every
reading (`gonio plan --list`), and the phrases for ranges, signature passes and durations."""

from __future__ import annotations

import math

import numpy as np

from gonio.config import InstrumentConfig
from gonio.plan.parse import AUTO_RANGE, KINDS, SIDES, Plan, SignaturePlan
from gonio.plan.schedule import Schedule


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
        f" (as written: {format_duration(sched.naive_estimate_s)})"
        + _emulated(sched.time_scale),
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


def _emulated(time_scale: float | None) -> str:
    """What the estimates are for when not for the real bench."""
    if time_scale is None:
        return ""
    pace = ("moves, settling and dwell at once" if math.isinf(time_scale) else "in real time"
            if time_scale == 1.0 else f"moves, settling and dwell {time_scale:g}x faster")
    return f" on the emulated bench (time_scale {time_scale:g}: {pace})"


def format_duration(seconds: float) -> str:
    """Seconds as h:mm:ss (and the raw seconds when short)."""
    s = int(round(seconds))
    text = f"{s // 3600}:{s % 3600 // 60:02d}:{s % 60:02d}"
    return f"{text} ({seconds:.1f} s)" if seconds < 600 else text
