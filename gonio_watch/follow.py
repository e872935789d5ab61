"""Following a run directory that another process writes: the new complete lines of
readings.jsonl, checked by the store's own LineChecker, and meta.json, each read again only
when a stat shows that its inode, size or modification time changed. The scan process knows
nothing of it: the store's lines are appended and fsynced one by one, so a stretch read here
ends in complete lines and at most a torn last line, which is simply not complete yet."""

from __future__ import annotations

import json
import os
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from gonio.store import META, READINGS, Run, damage_message

POLL_S = 0.25  # between two stats of the run's files


@dataclass(frozen=True)
class Snapshot:
    """What the run holds at one moment: meta.json, the valid readings in file order, the
    damage report (the rules every reader applies, gonio.store.Run.problems; None: none) and
    whether a line is being written (a torn tail)."""

    meta: dict[str, Any]
    rows: list[dict[str, Any]]
    damage: str | None
    torn: bool


def _stamp(path: Path) -> tuple[int, int, int] | None:
    """(inode, size, mtime ns) of a file, None if it is not there."""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        return None
    return st.st_ino, st.st_size, st.st_mtime_ns


class RunFollower:
    """Reads what a run directory gained since the last `poll` (thread-safe; `follow` polls
    on a thread of its own)."""

    def __init__(self, run: Run):
        self.run = run
        self._lock = threading.Lock()
        self._meta, self._meta_stamp = run.meta, None
        self._restart()

    def _restart(self) -> None:
        """Forget the lines read (the file was replaced or cut below what was read)."""
        self._checker = self.run.line_checker()
        self._rows: list[dict[str, Any]] = []
        self._offset = self._torn = 0
        self._stamp: tuple[int, int, int] | None = None

    def poll(self) -> None:
        """Read meta.json and the new lines of readings.jsonl if either changed."""
        with self._lock:
            self._poll_meta()
            self._poll_readings()

    def _poll_meta(self) -> None:
        path = self.run.path / META
        stamp = _stamp(path)
        if stamp is None or stamp == self._meta_stamp:
            return
        try:
            self._meta = json.loads(path.read_text())
        except (OSError, ValueError):
            return  # replaced atomically by the scan; a failed read is retried next poll
        self._meta_stamp = stamp

    def _poll_readings(self) -> None:
        path = self.run.path / READINGS
        stamp = _stamp(path)
        if stamp is None or stamp == self._stamp:
            return
        if self._stamp is not None and (stamp[0] != self._stamp[0] or stamp[1] < self._offset):
            self._restart()
        with open(path, "rb") as fh:
            fh.seek(self._offset)
            data = fh.read()
        keep = data.rfind(b"\n") + 1
        self._rows.extend(self._checker.feed(data[:keep]))
        self._offset += keep
        self._torn = len(data) - keep
        self._stamp = stamp

    def snapshot(self) -> Snapshot:
        """The run as last polled."""
        with self._lock:
            lines = self._checker.lines(self._offset, self._torn)
            problems = self.run.problems(lines, self._meta)
            damage = (damage_message(self.run.path, lines, problems)
                      if lines.damaged or problems else None)
            return Snapshot(self._meta, list(self._rows), damage, self._torn > 0)

    def follow(self, stop: threading.Event, every_s: float = POLL_S) -> threading.Thread:
        """Poll every `every_s` seconds on a daemon thread until `stop` is set."""
        def loop() -> None:
            while True:
                self.poll()
                if stop.wait(every_s):
                    return

        thread = threading.Thread(target=loop, name="watch-follow", daemon=True)
        thread.start()
        return thread
