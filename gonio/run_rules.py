"""The rules of a run beyond its lines' own (gonio.store checks those) that every reader
applies: meta.json names a line checksum gonio reads (and, for `crc32+run`, the run's uid each
line must carry) and the digests; the readings reach the highest index its sessions record
(readings a cut file lost are damage, and resume measures them again), there are no fewer than
the count it records stored (`stored`), a completed run holds what it planned, and each
session follows the last. Plain functions of meta.json and the lines, below the store."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Protocol

CRC = "crc32"  # the line checksum's field, and the older scheme's name
RUN_UID = "run_uid"  # meta.json's key of the run's identity, which each line carries
LINE_CHECKSUM = "crc32+run"  # meta.json's "line_checksum" of a run gonio makes
LINE_CHECKSUMS = {LINE_CHECKSUM: True, CRC: False}  # the schemes read: lines carry the run's uid


class StoredLines(Protocol):
    """What the rules read of a run's checked lines (gonio.store.Lines)."""

    rows: list[dict[str, Any]]
    damaged: list[Any]

    @property
    def top(self) -> int: ...


def describe_indices(indices: list[int]) -> str:
    """Indices as "index 4" or "indices 4-6, 9"."""
    parts, start = [], None
    for i, k in enumerate(indices):
        if start is None:
            start = k
        if i + 1 == len(indices) or indices[i + 1] != k + 1:
            parts.append(str(k) if start == k else f"{start}-{k}")
            start = None
    return ("index " if len(indices) == 1 else "indices ") + ", ".join(parts)


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


def lost_indices(meta: dict[str, Any], lines: StoredLines) -> list[int]:
    """Indices meta.json records as stored beyond the last one the lines hold (a cut file),
    but for those a repair dropped (still to measure)."""
    dropped = set(meta.get("repair", {}).get("dropped", ()))
    return [i for i in range(lines.top + 1, recorded_top(meta) + 1) if i not in dropped]


def session_problems(meta: dict[str, Any], lines: StoredLines) -> list[str]:
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


def lost_and_session_problems(meta: dict[str, Any], lines: StoredLines, path: Path
                              ) -> list[str]:
    """Readings lost (`lost_indices`, with what to do) or, when none are, where the sessions
    and counts disagree with the readings (`session_problems`); one line each."""
    lost = lost_indices(meta, lines)
    if not lost:
        return session_problems(meta, lines)
    return [f"readings.jsonl ends at index {lines.top}, but meta.json records readings up to "
            f"index {recorded_top(meta)}: {describe_indices(lost)} lost (`gonio scan --resume "
            f"{path}` measures them again)"]
