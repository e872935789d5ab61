"""Whether a run holds what it planned: an incomplete run is one whose status is not
`completed`, whose stored readings are fewer than planned, or that was read with --force past
damage (gonio.store.Run.read_past, named in full). Every reader of a run says so in
one line (`Completeness.text`) and records the facts in its outputs (gonio.record carries
them); `gonio check` reports them beside the run's integrity."""

from __future__ import annotations

import fcntl
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from gonio.errors import GonioError
from gonio.store import READINGS, Run


@dataclass(frozen=True)
class Completeness:
    """A run's status (and its reason), the readings it stores, the readings it planned
    (None: unknown, a run that recorded no count and whose plan no longer schedules) and the
    damage a read with --force went past (one entry each)."""

    status: str
    reason: str
    stored: int
    planned: int | None
    damage: tuple[str, ...] = ()

    @property
    def complete(self) -> bool:
        """Status `completed`, no fewer readings stored than planned and no damage read past."""
        return self.status == "completed" and not self.damage and (
            self.planned is None or self.stored >= self.planned)

    def counts(self) -> str:
        """"N of M readings" (stored of planned)."""
        return f"{self.stored} of {'?' if self.planned is None else self.planned} readings"

    def text(self) -> str:
        """One line: complete or incomplete, N of M readings, the status and its reason, and
        the damage read past."""
        why = f" ({self.reason})" if self.reason else ""
        past = f"; read with --force past damage: {'; '.join(self.damage)}" if self.damage \
            else ""
        return (f"{'complete' if self.complete else 'incomplete'} run: {self.counts()} stored, "
                f"status {self.status}{why}{past}")

    def to_json(self) -> dict[str, Any]:
        """The facts an output's header carries: status, reason, complete, stored_readings,
        planned_readings, and `damage` (what --force read past) when there is any."""
        out = {"status": self.status, "reason": self.reason, "complete": self.complete,
               "stored_readings": self.stored, "planned_readings": self.planned}
        return {**out, "damage": list(self.damage)} if self.damage else out

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> Completeness:
        """The completeness `to_json` gave."""
        return cls(data["status"], data["reason"], data["stored_readings"],
                   data["planned_readings"], tuple(data.get("damage", ())))


def planned_readings(run: Run, meta: Mapping[str, Any] | None = None) -> int | None:
    """The readings the run planned: meta.json's `planned` (`meta`, else the run's), else the
    stored plan scheduled on the stored config (runs that recorded no count); None if neither
    says."""
    meta = run.meta if meta is None else meta
    if isinstance(meta.get("planned"), int):
        return meta["planned"]
    from gonio.config import parse_config
    from gonio.plan import build_schedule, parse_plan

    try:
        return len(build_schedule(parse_plan(run.plan, run.path / "plan.toml"),
                                  parse_config(run.config, run.path / "instrument.toml")))
    except GonioError:
        return None


def completeness_of(run: Run, stored: int | None = None,
                    meta: Mapping[str, Any] | None = None) -> Completeness:
    """The run's completeness; `stored`: its valid readings if the caller has counted them
    (else its lines are read); `meta`: its meta.json as read since the run was opened (a
    watcher's snapshot), else the run's. A run opened with force names the damage read past."""
    if stored is None:
        stored = len(run.lines().rows)
    meta = run.meta if meta is None else meta
    return Completeness(meta.get("status", "unknown"), meta.get("reason", ""), stored,
                        planned_readings(run, meta), tuple(run.read_past))


def being_written(run: Run) -> bool:
    """Whether a scan holds the run open to append to it (its readings file is locked)."""
    with open(run.path / READINGS, "rb") as fh:
        try:
            fcntl.flock(fh.fileno(), fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            return True
        fcntl.flock(fh.fileno(), fcntl.LOCK_UN)
    return False
