"""`gonio queue add|list|run`: plans run one after another, unattended, into one output folder.

`add` validates each plan as `gonio plan` does and queues a copy of it (OUT/queue.toml);
`list` prints one line per entry, naming what it cannot read (an entry, a run directory; exit
1 then); `run` works through the entries not completed, in order, each as `gonio scan` would
run it, and after a crash resumes the one that was running. A run that fails stops the queue
(unless --keep-going); one aborted (Ctrl-C twice, SIGTERM) always does. The exit status: 0
all completed, 1 a run failed, 130 aborted by Ctrl-C, 128 + N ended by signal N.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from gonio_cli.commands.scan import add_sim_option, plan_given_to_sim, report, warner

if TYPE_CHECKING:
    from gonio.queue import Entry

VERB = "gonio queue"


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the `queue` verb and its `add`, `list` and `run` actions."""
    p = subparsers.add_parser("queue", help="run plans one after another, crash-safe",
                              description=__doc__)
    actions = p.add_subparsers(dest="action", metavar="ACTION")
    actions.required = True
    out_help = "the queue's folder, where its run directories go (default: ./runs)"

    a = actions.add_parser("add", help="validate plans and append them to the queue")
    a.add_argument("plans", nargs="*", metavar="PLAN", help="plan TOML files, in run order")
    a.add_argument("--instrument", metavar="CFG",
                   help="instrument config (default: each plan's `instrument`)")
    add_sim_option(a)
    a.add_argument("--out", default="runs", metavar="DIR", help=out_help)
    a.set_defaults(func=add)

    ls = actions.add_parser("list", help="one line per entry: position, plan, instrument, "
                                         "sim, state, run directory, readings stored/planned "
                                         "(and what cannot be read)")
    ls.add_argument("--out", default="runs", metavar="DIR", help=out_help)
    ls.set_defaults(func=list_entries)

    r = actions.add_parser("run", help="run the entries not completed, in order")
    r.add_argument("--out", default="runs", metavar="DIR", help=out_help)
    r.add_argument("--keep-going", action="store_true",
                   help="after a failed run go on with the next entry (exit 1 at the end)")
    r.add_argument("--no-plot", action="store_true", help="do not write plot.png")
    r.add_argument("--no-progress", action="store_true", help="no progress bar")
    r.set_defaults(func=run)


def line(out: Path, position: int, entry: Entry) -> str:
    """An entry as `gonio queue add` and `list` print it."""
    return described(out, position, entry)[0]


def described(out: Path, position: int, entry: Entry, entries: list[Entry] | None = None
              ) -> tuple[str, bool]:
    """(line, whether it names a problem): an entry's line, ending with why its run directory
    cannot be read or, given the queue's `entries`, cannot be this entry's."""
    from gonio.queue import readings_of, run_problem

    stored, planned, unreadable = readings_of(out, entry)
    refused = run_problem(out, entry, entry.run, entries) \
        if entries is not None and entry.run and not unreadable else None
    sim = ("sim" if entry.sim else "real") if isinstance(entry.sim, bool) \
        else "sim:" + ",".join(entry.sim)
    run_dir = out / entry.run if entry.run else "-"
    text = (f"{position}  {entry.source}  {entry.instrument}  {sim}  {entry.state}  {run_dir}  "
            f"{'?' if stored is None else stored}/{planned}"
            + (f"  (cannot read: {unreadable})" if unreadable else "")
            + (f"  (not this entry's run: {refused})" if refused else ""))
    return text, bool(unreadable or refused)


def add(args: argparse.Namespace) -> int:
    """Queue the plans (all or none) and print their entries."""
    from gonio.errors import PlanError
    from gonio.queue import add as add_plans

    taken, sim = plan_given_to_sim(args.sim)
    plans = [taken, *args.plans] if taken else args.plans
    if not plans:
        raise PlanError("give at least one PLAN file to queue")
    out = Path(args.out)
    for position, entry in add_plans(out, plans, args.instrument, sim or False):
        print(line(out, position, entry))
    return 0


def list_entries(args: argparse.Namespace) -> int:
    """Print the queue, one line per entry, an entry it cannot read as the line naming why;
    1 if any entry or run directory could not be read."""
    from gonio.errors import QueueError
    from gonio.queue import existing, survey

    out = Path(args.out)
    surveyed = survey(out)
    if not surveyed:
        existing(out)  # its error: no queue here
    readable = [e for e in surveyed if not isinstance(e, QueueError)]
    printed = [(f"{position}  cannot read: {entry}", True) if isinstance(entry, QueueError)
               else described(out, position, entry, readable)
               for position, entry in enumerate(surveyed, 1)]
    print("\n".join(text for text, _ in printed))
    return 1 if any(named for _, named in printed) else 0


def run(args: argparse.Namespace) -> int:
    """Run the queue to its end, or to the first run that fails or is aborted."""
    from drivers.base import DriverError
    from gonio.engine import PauseControl
    from gonio.errors import GonioError
    from gonio.queue import identify, next_position, reason_of, run_entry, run_lock

    out, progress = Path(args.out), False if args.no_progress else None
    failed: list[int] = []  # positions, as printed when each failed
    passed: set[str] = set()  # ids of the entries that failed
    with run_lock(out), PauseControl() as control:
        while True:
            entries = identify(out)  # an entry added by hand meanwhile gets its id first
            position = next_position(entries, {n for n, e in enumerate(entries, 1)
                                                if e.id in passed})
            if position is None:
                break
            entry = entries[position - 1]
            what = "resuming" if entry.run else "starting"
            print(f"{VERB}: entry {position} of {len(entries)}: {what} {entry.source}",
                  file=sys.stderr)
            try:
                result = run_entry(out, entry.id, control, progress, warn=warner(VERB))
            except (GonioError, DriverError, OSError) as exc:
                if not args.keep_going:
                    raise
                print(f"{VERB}: entry {position} failed: {reason_of(exc)}", file=sys.stderr)
                failed.append(position)
                passed.add(entry.id)
                continue
            code = report(result, not args.no_plot, VERB)
            if code and (result.outcome.status == "aborted" or not args.keep_going):
                return code
            if code:
                failed.append(position)
                passed.add(entry.id)
    if failed:
        print(f"{VERB}: {len(failed)} of {len(entries)} entries failed: "
              f"{', '.join(map(str, failed))}", file=sys.stderr)
        return 1
    print(f"{VERB}: all {len(entries)} entries completed", file=sys.stderr)
    return 0
