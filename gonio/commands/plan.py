"""`gonio plan PLAN`: validate a plan against an instrument, print its summary and duration
estimate (optimised order beside the order as written). Nothing moves."""

from __future__ import annotations

import argparse


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the `plan` verb."""
    p = subparsers.add_parser("plan", help="validate a plan and estimate its duration",
                              description=__doc__)
    p.add_argument("plan", help="plan TOML file")
    p.add_argument("--instrument", metavar="CFG",
                   help="instrument config (default: the plan's `instrument`)")
    p.add_argument("--list", action="store_true",
                   help="also print every reading in run order with its stage targets")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Print the summary; errors are PlanError/ConfigError lines."""
    from gonio.config import load_config
    from gonio.plan import build_schedule, listing, load_plan, summary
    from gonio.runner import instrument_path

    plan = load_plan(args.plan)
    cfg = load_config(instrument_path(plan, args.instrument))
    sched = build_schedule(plan, cfg)
    print(summary(plan, cfg, sched))
    if args.list:
        print(listing(sched))
    return 0
