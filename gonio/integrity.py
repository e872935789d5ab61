"""The rules of a run that every reader applies (`record_problems`, beside the lines'
own, gonio.store.scan_lines), checking a run directory (`gonio check`) and writing a repaired
copy of a damaged one.

The rules: meta.json names a line checksum gonio reads (and, for `crc32+run`, the run's uid
each line must carry) and the digests of plan.json, config.json and the register maps, which
must match; the readings reach the highest index its sessions record (readings a cut file lost
are damage, and resume measures them again), there are no fewer than the count it records
stored (`stored`), a completed run holds what it planned, and each session follows the last.
A check also reports whether the run holds what it planned (gonio.completeness: an intact run
short of its plan is "intact but incomplete", not "clean"). A repaired copy is a new run
directory with every valid reading under its own index (a valid line out of order included);
the indices it lacks are listed in meta.json's `repair.dropped`, and `gonio scan --resume
COPY` measures exactly those (then whatever the run had not reached). A run directory whose
meta.json is lost is repaired too: gonio.recovery rebuilds it.
"""

from __future__ import annotations

import os
import secrets
import shutil
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from gonio.completeness import Completeness, completeness_of
from gonio.errors import RunError
from gonio.store import (
    LINE_CHECKSUM,
    LINE_CHECKSUMS,
    META,
    READINGS,
    RUN_UID,
    Lines,
    Run,
    describe_indices,
    digest_problems,
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


def meta_problems(meta: dict[str, Any]) -> list[str]:
    """What meta.json lacks for the run to be checked: a line checksum gonio reads (and the
    run's uid its lines carry), the digests."""
    scheme, problems = meta.get("line_checksum"), []
    if scheme is None:
        problems.append("meta.json names no line_checksum: the lines cannot be checked")
    elif scheme not in LINE_CHECKSUMS:
        problems.append(f"meta.json's line_checksum {scheme!r} is none gonio reads "
                        f"({', '.join(LINE_CHECKSUMS)})")
    elif LINE_CHECKSUMS[scheme] and not isinstance(meta.get(RUN_UID), str):
        problems.append(f"meta.json has no {RUN_UID}: the lines' run cannot be checked")
    if not meta.get("digests"):
        problems.append("meta.json records no digests: plan.json, config.json and the "
                        "register maps cannot be checked")
    return problems


def recorded_top(meta: dict[str, Any]) -> int:
    """The highest index meta.json's sessions record as stored (-1: none): each ended
    session's last index, and the index before each session's first."""
    tops = [-1]
    for s in meta.get("sessions", []):
        tops += [s[key] - shift for key, shift in (("last_index", 0), ("first_index", 1))
                 if isinstance(s.get(key), int)]
    return max(tops)


def lost_indices(meta: dict[str, Any], lines: Lines) -> list[int]:
    """Indices meta.json records as stored beyond the last one the lines hold (a cut file),
    but for those a repair dropped (still to measure)."""
    dropped = set(meta.get("repair", {}).get("dropped", ()))
    return [i for i in range(lines.top + 1, recorded_top(meta) + 1) if i not in dropped]


def session_problems(meta: dict[str, Any], lines: Lines) -> list[str]:
    """Where meta.json's sessions, stored count and status disagree with the readings stored
    (other than readings lost, `lost_indices`, and the counts damaged lines account for)."""
    problems, prev = [], None
    for k, s in enumerate(meta.get("sessions", []), 1):
        first = s.get("first_index", 0)
        if prev is not None and "refill" not in s and first != prev.get(
                "last_index", first - 1) + 1:
            problems.append(f"session {k} starts at index {first}, not after session {k - 1} "
                            f"(which ended at index {prev.get('last_index')})")
        prev = s
    stored, planned = meta.get("stored"), meta.get("planned")
    if lines.damaged:  # the readings they held are what the counts miss
        return problems
    if isinstance(stored, int) and len(lines.rows) < stored:
        problems.append(f"meta.json records {stored} readings stored, but readings.jsonl "
                        f"holds {len(lines.rows)}")
    elif meta.get("status") == "completed" and planned is not None and len(
            lines.rows) != planned:
        problems.append(f"meta.json says completed, {planned} readings planned, but "
                        f"{len(lines.rows)} are stored")
    return problems


def record_problems(run: Run, lines: Lines, meta: dict[str, Any] | None = None) -> list[str]:
    """Every rule of the run but its lines' own, broken (one line each): meta.json
    (`meta`, else the run's) and its digests, readings lost, the sessions and counts."""
    meta = run.meta if meta is None else meta
    lost = lost_indices(meta, lines)
    said = ([f"readings.jsonl ends at index {lines.top}, but meta.json records readings up to "
             f"index {recorded_top(meta)}: {describe_indices(lost)} lost (`gonio scan --resume "
             f"{run.path}` measures them again)"] if lost else [])
    return (meta_problems(meta) + digest_problems(run) + said
            + ([] if lost else session_problems(meta, lines)))


def check(run: Run, found: Sequence[str] = ()) -> Report:
    """Verify every line, the digests, the sessions and the counts of a run; `found`: problems
    found before it could be opened (a lost meta.json, gonio.recovery)."""
    lines = run.lines()
    problems = [*found, *record_problems(run, lines)]
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
    repairable = bool(lines.damaged or set(problems) - set(digest_problems(run)))
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
