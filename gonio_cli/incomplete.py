"""The one gate every reader of a run passes and the one stderr line it prints: a verb that
reads runs names the arguments holding them (`reads_run`, set by its parser), and the command
line, after the verb's argument checks that need no run (`check_args`, set by its parser: bad
input gives its one error line alone) and before the verb runs, refuses a damaged run (by the
rules `gonio check` applies, gonio.store.Run.problems: one error line, exit 2) unless --force
(`add_force_option`), and names each incomplete run (gonio.completeness) in one warning line,
a run read past damage included."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterable
from typing import TYPE_CHECKING

from gonio.errors import GonioError

if TYPE_CHECKING:
    from gonio.store import Run

FORCE_HELP = ("read a damaged run (one `gonio check` calls damaged): its valid readings, "
              "every output's header naming the damage read past (refused otherwise)")


def add_force_option(p: argparse.ArgumentParser, also: str = "") -> None:
    """--force of a verb that reads runs (`also`: what else it forces, said after)."""
    p.add_argument("--force", action="store_true", help=FORCE_HELP + also)


def runs_read(args: argparse.Namespace) -> list[str]:
    """The run directories the verb reads: the arguments its parser names in `reads_run` (a
    destination or a tuple of them, each one directory or a list; none where it is not given,
    as with --import)."""
    dests = getattr(args, "reads_run", None) or ()
    out: list[str] = []
    for dest in (dests,) if isinstance(dests, str) else dests:
        value = getattr(args, dest, None)
        if value is not None:
            out += [value] if isinstance(value, str) else list(value)
    return out


def gate_runs(verb: str, args: argparse.Namespace) -> None:
    """Raise DamagedRunError (one line) for a damaged run the verb reads, unless --force;
    print `VERB: warning: RUN: incomplete run: N of M readings stored, status S (reason)` for
    each incomplete run (with what --force read past); a run a scan is still writing is in
    progress, not incomplete, and a directory that is no run is left to the verb's own error
    (one line)."""
    from gonio.completeness import being_written, completeness_of
    from gonio.store import DamagedRunError, open_run

    force = bool(getattr(args, "force", False))
    for path in runs_read(args):
        try:
            run = open_run(path, force=force)
        except (GonioError, OSError):
            continue
        try:
            lines = run.refuse_damage()
        except DamagedRunError:
            raise
        except (GonioError, OSError):
            continue
        if being_written(run) and not run.read_past:
            continue
        found = completeness_of(run, len(lines.rows))
        if not found.complete:
            print(f"{verb}: warning: {path}: {found.text()}", file=sys.stderr, flush=True)


def incomplete_notes(runs: Iterable[Run]) -> list[str]:
    """`RUN: incomplete run: ...` for each incomplete run, for an output's notes."""
    from gonio.completeness import completeness_of

    found = [(run, completeness_of(run)) for run in runs]
    return [f"{run.path}: {c.text()}" for run, c in found if not c.complete]
