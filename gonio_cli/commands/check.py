"""`gonio check RUN [--repair OUT_DIR]`: verify a run (every line of readings.jsonl, plan.json,
config.json and the register maps against the digests recorded at the start, the sessions)
and print what is wrong, and how many readings of how many planned it holds, with its status.
The last line says `clean` (intact and complete), `intact but incomplete: N of M readings
stored, status S` (stopped short of its plan: `gonio scan --resume RUN` continues it), or
`damaged`. The exit status answers whether the run's files are intact: 0 intact, complete or
not (a torn last line is not damage), 1 damaged.
`--repair OUT_DIR` then writes a repaired copy there: every valid reading under its own
index, the dropped ones listed in its meta.json, and `gonio scan --resume OUT_DIR` measures
exactly those; the copy's path is the last line printed."""

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
    from gonio.store import DamagedRunError, open_run

    try:
        report = check(open_run(args.run))
    except DamagedRunError as exc:  # meta.json, plan.json or config.json unreadable
        print(f"{exc}\ndamaged")
        return 1
    out = repair(report, Path(args.repair)) if args.repair and report.lines.damaged else None
    print(report.text())
    if out is not None:
        print(f"repaired copy: {len(report.lines.rows)} readings kept; "
              f"`gonio scan --resume {out}` measures the missing ones\n{out}")
    elif args.repair:
        print("nothing to repair in readings.jsonl (--repair mends only its lines)")
    return 1 if report.damaged else 0
