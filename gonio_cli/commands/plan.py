"""`gonio plan PLAN`: validate a plan against an instrument, print its summary and duration
estimate (optimised order beside the order as written), with --sim on the emulated bench at its
[sim] time_scale. Nothing moves."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from gonio.config import InstrumentConfig
    from gonio.plan import Plan
    from gonio.simulate import TablesEstimate


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the `plan` verb."""
    p = subparsers.add_parser("plan", help="validate a plan and estimate its duration",
                              description=__doc__)
    p.add_argument("plan", help="plan TOML file")
    p.add_argument("--instrument", metavar="CFG",
                   help="instrument config (default: the plan's `instrument`)")
    p.add_argument("--list", action="store_true",
                   help="also print every reading in run order with its stage targets")
    p.add_argument("--sim", action="store_true",
                   help="estimate the duration on the emulated bench (`gonio scan --sim`): "
                        "moves, settling and dwell at the config's [sim] time_scale")
    p.add_argument("--time-scale", type=float, metavar="X",
                   help="with --sim: virtual seconds per real second (inf = instant moves), "
                        "instead of the config's [sim] time_scale")
    p.set_defaults(func=run)


def description(plan: Plan, cfg: InstrumentConfig) -> str:
    """What the run's record will say of the sample and the bench ([sample], [optics]), or
    where to add them: a run lacking either reduces only with a calibration's help."""
    sample, optics = plan.sample, cfg.optics
    lines = [f"  sample: {sample.id!r}, {sample.kind}"
             + (f", eta {sample.eta:g}" if sample.eta is not None else "")
             + (f", k {sample.k:g}" if sample.k else "") + f", lit from {sample.lit_from}"
             + (f", a reference for the {sample.reference}" if sample.reference else "")
             if sample else "  sample: none (add a [sample] table to the plan: id, kind, eta)"]
    if optics:
        lines.append(f"  optics: {optics.wavelength_nm:g} nm ({optics.bandwidth_nm:g} nm FWHM), "
                     f"beam {optics.beam_diameter_mm:g} mm, divergence "
                     f"{optics.divergence_deg:g} deg; receiver {optics.aperture_diameter_mm:g} mm"
                     f" at {optics.aperture_distance_mm:g} mm = "
                     f"{optics.receiver_solid_angle_sr:.4g} sr; polarisation source "
                     f"{_state(optics.source_polarisation)}, analyser "
                     f"{_state(optics.analyser_polarisation)}")
    else:
        lines.append("  optics: none (add an [optics] table to the instrument config, or "
                     "reduce with a calibration that measured the aperture)")
    return "\n".join(lines)


def tables_line(tables: TablesEstimate, estimate_s: float) -> str:
    """The emulated bench's table preparation before the first move (every reading evaluated
    once, and the planes the cache lacks walked; this machine, now), and the duration with it:
    the tables cached and cold."""
    from gonio.plan import format_duration

    if tables.evaluate_s:
        evaluating = (f"; evaluating every reading once before the first move about "
                      f"{format_duration(tables.evaluate_s)}")
        cached_s = estimate_s + tables.evaluate_s
    else:
        evaluating, cached_s = "", estimate_s
    if not tables.planes:
        cached = f", duration with it {format_duration(cached_s)}" if evaluating else ""
        return ("  multiple-scattering tables: none to walk (cached, or none needed)"
                + evaluating + cached)
    return (f"  multiple-scattering tables: {tables.planes} planes to walk before the first move "
            f"({tables.walks} walks each), about {format_duration(tables.seconds)} on this "
            f"machine now{evaluating}; duration with the tables cached "
            f"{format_duration(cached_s)}, cold {format_duration(cached_s + tables.seconds)}")


def _state(polarisation: str | float) -> str:
    """A polarisation state as text: its name, or a linear polariser's angle in degrees."""
    return polarisation if isinstance(polarisation, str) else f"linear at {polarisation:g} deg"


def run(args: argparse.Namespace) -> int:
    """Print the summary; errors are PlanError/ConfigError lines."""
    from gonio.config import load_config
    from gonio.plan import build_schedule, listing, load_plan, summary
    from gonio.runner import instrument_path, scaled

    plan = load_plan(args.plan)
    cfg = scaled(load_config(instrument_path(plan, args.instrument)), args.sim, args.time_scale)
    time_scale = None
    if args.sim:
        from gonio.simulate import emulated_time_scale

        time_scale = emulated_time_scale(cfg)
    sched = build_schedule(plan, cfg, time_scale)
    print(summary(plan, cfg, sched))
    if args.sim:
        from gonio.simulate import beam_over_range, tables_estimate

        print(tables_line(tables_estimate(cfg, plan, sched), sched.estimate_s))
        if (full_scale := beam_over_range(cfg, plan, sched)) is not None:
            print(f"  beam: the emulated beam reaches its [beam] range's full scale "
                  f"({full_scale:g} W): its beam readings over it are flagged saturated and "
                  "left out of the normalisation (a larger [beam] range keeps them all, at a "
                  "smaller share of its full scale)")
    print(description(plan, cfg))
    if args.list:
        print(listing(sched))
    return 0
