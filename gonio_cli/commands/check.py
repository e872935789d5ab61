"""`gonio check RUN [--repair OUT_DIR]`: verify a run by the rules every reader applies
(gonio.integrity, gonio.run_rules: every line of readings.jsonl with its checksum and run
identity, plan.json, config.json and the register maps against the digests recorded at the
start, the sessions and the count of readings stored) and print what is wrong, and how many
readings of how many planned it holds, with its status. The last line says `clean` (intact and
complete), `intact but incomplete: N of M readings stored, status S` (stopped short of its
plan: `gonio scan --resume RUN` continues it), or `damaged`. The exit status answers whether
the run's files are intact: 0 intact, complete or not (a torn last line is not damage), 1
damaged. `--repair OUT_DIR` then writes a repaired copy there: every valid reading under its own
index (out of order or not), the missing ones (dropped, or lost from a cut file) listed in its
meta.json, and `gonio scan --resume OUT_DIR` measures exactly those; a run that lost its
meta.json gets one rebuilt from its readings, plan and config (gonio.recovery). The copy's
path is the last line printed."""

from __future__ import annotations

import argparse
from pathlib import Path


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the `check` verb."""
    p = subparsers.add_parser("check", help="verify a run; write a repaired copy",
                              description=__doc__)
    p.add_argument("run", help="run directory")
    p.add_argument("--repair", metavar="OUT_DIR",
                   help="write a repaired copy of a damaged run to this new directory")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Print the report (and repair); 0 intact (complete or not), 1 damaged."""
    from gonio.integrity import check, repair
    from gonio.recovery import lost_meta, recovered_run
    from gonio.store import DamagedRunError, open_run

    found: list[str] = []
    try:
        stored = open_run(args.run)
    except DamagedRunError as exc:  # meta.json, plan.json or config.json lost or unreadable
        if not (args.repair and lost_meta(Path(args.run))):
            print(f"{exc}\ndamaged")
            return 1
        stored, found = recovered_run(Path(args.run)), ["meta.json is missing: rebuilt from "
                                                         "the readings, plan and config"]
    report = check(stored, found)
    out = repair(report, Path(args.repair)) if args.repair and report.repairable else None
    print(report.text())
    if out is not None:
        print(f"repaired copy: {len(report.lines.rows)} readings kept; "
              f"`gonio scan --resume {out}` measures the missing ones\n{out}")
    elif args.repair:
        print("nothing to repair (--repair mends the readings and meta.json, not a changed "
              "plan.json, config.json or register map)")
    return 1 if report.damaged else 0
