"""Checking a run directory (`gonio check`) and writing a repaired copy of a damaged one.

A check reads every line of readings.jsonl (see `gonio.store.scan_lines`), compares plan.json,
config.json and the register maps with the digests meta.json recorded at the start, checks
that the sessions' first/last indices agree with the lines, and reports whether the run holds
what it planned (gonio.completeness: an intact run short of its plan is "intact but
incomplete", not "clean"). A repaired copy is a new
run directory with every valid reading under its own index; the indices it lacks are listed
in meta.json's `repair.dropped`, and `gonio scan --resume COPY` measures exactly those (then
whatever the run had not reached).
"""

from __future__ import annotations

import os
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from gonio.completeness import Completeness, completeness_of
from gonio.errors import RunError
from gonio.store import (
    CRC,
    META,
    READINGS,
    Lines,
    Run,
    describe_indices,
    digest_problems,
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


def session_problems(meta: dict[str, Any], lines: Lines) -> list[str]:
    """Where meta.json's sessions and status disagree with the readings stored."""
    problems, prev = [], None
    for k, s in enumerate(meta.get("sessions", []), 1):
        first, last = s.get("first_index", 0), s.get("last_index")
        if first > lines.top + 1:
            problems.append(f"session {k} starts at index {first} but the readings end at "
                            f"index {lines.top}")
        if last is not None and last > lines.top:
            problems.append(f"session {k} stored readings up to index {last} but the "
                            f"readings end at index {lines.top}")
        if prev is not None and "refill" not in s and first != prev.get(
                "last_index", first - 1) + 1:
            problems.append(f"session {k} starts at index {first}, not after session {k - 1} "
                            f"(which ended at index {prev.get('last_index')})")
        prev = s
    planned = meta.get("planned")
    if meta.get("status") == "completed" and planned is not None and len(lines.rows) != planned:
        problems.append(f"meta.json says completed, {planned} readings planned, but "
                        f"{len(lines.rows)} are stored")
    return problems


def check(run: Run) -> Report:
    """Verify every line, the digests and the sessions of a run."""
    lines = run.lines()
    problems = digest_problems(run) + session_problems(run.meta, lines)
    notes = []
    if lines.torn_bytes:
        notes.append(f"a torn last line ({lines.torn_bytes} bytes after the last newline): "
                     f"ignored, cut when the run is resumed")
    if lines.unchecked:
        notes.append(f"{lines.unchecked} lines carry no {CRC} (written before line checksums):"
                     f" unchecked")
    if not run.meta.get("digests"):
        notes.append("no digests recorded (a run made before them): plan.json and config.json "
                     "unchecked")
    pending = run.meta.get("repair", {}).get("dropped", [])
    if lines.missing() and pending:
        notes.append(f"repaired copy: {describe_indices(lines.missing())} still to measure "
                     f"(gonio scan --resume {run.path})")
    return Report(run, lines, problems, notes, completeness_of(run, len(lines.rows)))


def repair(report: Report, out: Path) -> Path:
    """Write a repaired copy of the checked run to the new directory `out`: the valid readings
    under their own indices, meta.json with a `repair` record (source, dropped indices,
    damaged lines) and, if anything was lost, status `failed` so that resume completes it."""
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
    checked = run.meta.get("line_checksum") == CRC
    with open(tmp / READINGS, "wb") as fh:
        fh.write(b"".join(encode_line(r, checksum=checked) for r in lines.rows))
        fh.flush()
        os.fsync(fh.fileno())
    dropped = lines.missing()
    meta = {**run.meta, "repair": {
        "from": str(run.path.resolve()), "utc": utc_now(), "kept": len(lines.rows),
        "dropped": dropped, "torn_bytes": lines.torn_bytes, "previous": run.meta.get("repair"),
        "damaged_lines": [{"line": d.line, "problem": d.problem} for d in lines.damaged]}}
    if lines.damaged:
        lost = describe_indices(dropped) if dropped else "no index below the last stored one"
        meta.update(status="failed", reason=f"repaired copy of {run.path.name}: "
                    f"{len(lines.damaged)} damaged lines dropped, {lost} missing; "
                    f"gonio scan --resume measures what is missing")
    write_json_atomic(tmp / META, meta)
    os.rename(tmp, out)
    fsync_dir(out.parent)
    return out
