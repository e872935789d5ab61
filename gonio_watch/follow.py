"""Following a run directory that another process writes: the new complete lines of
readings.jsonl, checked by the store's own LineChecker, and meta.json, each read again only
when a stat shows that its inode, size or modification time changed. The scan process knows
nothing of it: the store's lines are appended and fsynced one by one, so a stretch read here
ends in complete lines and at most a torn last line, which is simply not complete yet."""

from __future__ import annotations

import json
import threading
from dataclasses import dataclass
from typing import Any

from gonio.errors import os_error_text
from gonio.file_changes import read_changed
from gonio.store import META, READINGS, Run, damage_message
from gonio_watch.gate import Notices

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


class RunFollower:
    """Reads what a run directory gained since the last `poll` (thread-safe; `follow` polls
    on a thread of its own). A file it cannot read is told to `notices` once, then retried."""

    def __init__(self, run: Run, notices: Notices | None = None):
        self.run = run
        self.notices = notices or Notices()
        self._lock = threading.Lock()
        self._meta, self._meta_stamp = run.meta, None
        self._trouble: str | None = None  # the problem last told
        self._restart()

    def _restart(self) -> None:
        """Forget the lines read (the file was replaced or cut below what was read)."""
        self._checker = self.run.line_checker()
        self._rows: list[dict[str, Any]] = []
        self._offset = self._torn = 0
        self._stamp: tuple[int, int, int] | None = None

    def poll(self) -> None:
        """Read meta.json and the new lines of readings.jsonl if either changed; a file that
        cannot be read (replaced by a folder or a FIFO, say) is told once and tried again at
        the next poll."""
        with self._lock:
            try:
                self._poll_meta()
                self._poll_readings()
            except OSError as exc:
                trouble = os_error_text(exc)
                if trouble != self._trouble:
                    self.notices.note("follow", f"the live view cannot read the run: {trouble}")
                self._trouble = trouble
            else:
                self._trouble = None

    def _poll_meta(self) -> None:
        read = read_changed(self.run.path / META, self._meta_stamp, 0)
        if read is None:
            return
        try:
            self._meta = json.loads(read[1])
        except ValueError:
            return  # replaced atomically by the scan; a failed read is retried next poll
        self._meta_stamp = read[0]

    def _poll_readings(self) -> None:
        read = read_changed(self.run.path / READINGS, self._stamp, self._offset)
        if read is None:
            return
        stamp, data = read
        if self._stamp is not None and (stamp[0] != self._stamp[0] or stamp[1] < self._offset):
            self._restart()
            stamp, data = read_changed(self.run.path / READINGS, None, 0) or (stamp, b"")
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
