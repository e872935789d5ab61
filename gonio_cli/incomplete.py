"""The one stderr line every reader of a run prints for an incomplete run (gonio.completeness):
a verb that reads runs names the arguments holding them (`reads_run`, set by its parser), and
the command line says it once, after the verb's argument checks that need no run
(`check_args`, set by its parser: bad input gives its one error line alone) and before the
verb runs."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterable
from typing import TYPE_CHECKING

from gonio.errors import GonioError

if TYPE_CHECKING:
    from gonio.store import Run


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


def warn_incomplete(verb: str, args: argparse.Namespace) -> None:
    """Print `VERB: warning: RUN: incomplete run: N of M readings stored, status S (reason)`
    for each incomplete run the verb reads; a run a scan is still writing is in progress, not
    incomplete, and a directory that is no run, or a damaged run, is left to the verb's own
    error (one line)."""
    from gonio.completeness import being_written, completeness_of
    from gonio.store import open_run

    for path in runs_read(args):
        try:
            run = open_run(path)
            lines = run.lines()
            if lines.damaged or being_written(run):
                continue
            found = completeness_of(run, len(lines.rows))
        except (GonioError, OSError):
            continue
        if not found.complete:
            print(f"{verb}: warning: {path}: {found.text()}", file=sys.stderr, flush=True)


def incomplete_notes(runs: Iterable[Run]) -> list[str]:
    """`RUN: incomplete run: ...` for each incomplete run, for an output's notes."""
    from gonio.completeness import completeness_of

    found = [(run, completeness_of(run)) for run in runs]
    return [f"{run.path}: {c.text()}" for run, c in found if not c.complete]
