"""Checking a run directory (`gonio check`) and writing a repaired copy of a damaged one.

A check applies the rules every reader applies (gonio.store's lines: checksum, the run's
identity, index order; gonio.run_rules: meta.json's line checksum, run uid and digests,
readings a cut file lost, counts and sessions; the digests of plan.json, config.json and the
register maps) and reports whether the run holds what it planned (gonio.completeness: an
intact run short of its plan is "intact but incomplete", not "clean"). A repaired copy is a
new run directory with every valid reading under its own index (a valid line out of order
included); the indices it lacks are listed in meta.json's `repair.dropped`, and `gonio scan
--resume COPY` measures exactly those (then whatever the run had not reached). A run
directory whose meta.json is lost is repaired too: gonio.recovery rebuilds it.
"""

from __future__ import annotations

import os
import secrets
import shutil
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from gonio.completeness import Completeness, completeness_of
from gonio.errors import RunError
from gonio.run_rules import (
    LINE_CHECKSUM,
    LINE_CHECKSUMS,
    RUN_UID,
    describe_indices,
    recorded_top,
)
from gonio.store import (
    META,
    READINGS,
    Lines,
    Run,
    digests,
    encode_line,
    fsync_dir,
    utc_now,
    write_json_atomic,
)

COPIED = ("plan.toml", "instrument.toml", "plan.json", "config.json")


@dataclass
class Report:
    """What a check found: the lines, other problems (digests, sessions), notes, and whether
    the run holds what it planned (gonio.completeness)."""

    run: Run
    lines: Lines
    problems: list[str]
    notes: list[str]
    completeness: Completeness
    repairable: bool  # damage a repaired copy mends (all but changed digests)

    @property
    def damaged(self) -> bool:
        """Whether anything is wrong (a torn last line is not)."""
        return bool(self.lines.damaged or self.problems)

    def text(self) -> str:
        """The report, one finding a line."""
        lines = self.lines
        out = [f"{self.run.path}: {lines.count} complete lines, {len(lines.rows)} valid "
               f"readings, {len(lines.damaged)} damaged lines, status {self.run.status}"]
        out += [f"  {READINGS} line {d.line}: {d.problem}" for d in lines.damaged]
        out += [f"  {p}" for p in self.problems]
        out += [f"  note: {n}" for n in self.notes]
        out.append(f"  {self.completeness.text()}")
        out.append(self.verdict())
        return "\n".join(out)

    def verdict(self) -> str:
        """The last line: damaged; intact but incomplete (with the counts and status); or
        clean (intact and complete)."""
        if self.damaged:
            return "damaged"
        found = self.completeness
        if not found.complete:
            return f"intact but incomplete: {found.counts()} stored, status {found.status}"
        return "clean"


def check(run: Run, found: Sequence[str] = ()) -> Report:
    """Verify every line, the digests, the sessions and the counts of a run; `found`: problems
    found before it could be opened (a lost meta.json, gonio.recovery)."""
    lines = run.lines()
    problems = [*found, *run.problems(lines)]
    notes = []
    if lines.torn_bytes:
        notes.append(f"a torn last line ({lines.torn_bytes} bytes after the last newline): "
                     f"ignored, cut when the run is resumed")
    if run.meta.get("line_checksum") in LINE_CHECKSUMS and not LINE_CHECKSUMS[
            run.meta["line_checksum"]]:
        notes.append(f"line_checksum {run.meta['line_checksum']} (an older format): the lines "
                     f"carry no run identity, so lines of another run are not told apart")
    if lines.unchecked:
        notes.append(f"{lines.unchecked} lines carry no checksum: unchecked")
    pending = run.meta.get("repair", {}).get("dropped", [])
    if lines.missing() and pending:
        notes.append(f"repaired copy: {describe_indices(lines.missing())} still to measure "
                     f"(gonio scan --resume {run.path})")
    repairable = bool(lines.damaged or set(problems) - set(run.digest_damage))
    return Report(run, lines, problems, notes, completeness_of(run, len(lines.rows)), repairable)


def repair(report: Report, out: Path) -> Path:
    """Write a repaired copy of the checked run to the new directory `out`: the valid readings
    under their own indices (lines of this scheme, LINE_CHECKSUM, under the run's uid, a new
    one for a run that had none), meta.json with the digests (those recorded: a changed
    plan.json or config.json stays damage; the files' own where none were) and a `repair`
    record (source, dropped indices, problems, damaged lines) and, if any reading is missing,
    status `failed` so that resume measures it."""
    run, lines = report.run, report.lines
    if out.exists():
        raise RunError(f"{out}: already exists; --repair writes a new run directory")
    tmp = out.with_name(f".{out.name}.repairing")
    shutil.rmtree(tmp, ignore_errors=True)
    try:
        tmp.mkdir(parents=True)
    except OSError as exc:
        raise RunError(f"{out}: cannot make the repaired run directory ({exc.strerror})") from None
    for name in COPIED:
        if (run.path / name).exists():
            shutil.copyfile(run.path / name, tmp / name)
    uid = run.meta.get(RUN_UID) if isinstance(run.meta.get(RUN_UID), str) else \
        secrets.token_hex(8)
    with open(tmp / READINGS, "wb") as fh:
        fh.write(b"".join(encode_line(r, run_uid=uid) for r in lines.rows))
        fh.flush()
        os.fsync(fh.fileno())
    dropped = lines.missing() + list(range(lines.top + 1, recorded_top(run.meta) + 1))
    meta = {**run.meta, "line_checksum": LINE_CHECKSUM, RUN_UID: uid,
            "digests": run.meta.get("digests") or digests(run.plan, run.config),
            "stored": len(lines.rows), "repair": {
                "from": str(run.path.resolve()), "utc": utc_now(), "kept": len(lines.rows),
                "dropped": dropped, "torn_bytes": lines.torn_bytes,
                "previous": run.meta.get("repair"), "problems": report.problems,
                "damaged_lines": [{"line": d.line, "problem": d.problem}
                                  for d in lines.damaged]}}
    if dropped:
        meta.update(status="failed", reason=f"repaired copy of {run.path.name}: "
                    f"{len(lines.damaged)} damaged lines dropped, {describe_indices(dropped)} "
                    f"missing; gonio scan --resume measures what is missing")
    write_json_atomic(tmp / META, meta)
    os.rename(tmp, out)
    fsync_dir(out.parent)
    return out
