"""A file that another process writes, read again only when it changed: its stamp and new
bytes from one descriptor, opened without blocking or following a symlink (the live view's
follower reads a run's meta.json and readings.jsonl so)."""

from __future__ import annotations

import os
import stat
from pathlib import Path

from drivers.user_file import kind_of


def stamp(status: os.stat_result) -> tuple[int, int, int]:
    """(inode, size, mtime ns) of a file: what changes when it is written or replaced."""
    return status.st_ino, status.st_size, status.st_mtime_ns


def read_changed(path: Path, seen: tuple[int, int, int] | None, offset: int
                 ) -> tuple[tuple[int, int, int], bytes] | None:
    """The stamp of the regular file `path` and its bytes from `offset`, both from one
    descriptor (a rename meanwhile cannot mix two files); None if it is not there or a stat
    shows the stamp `seen` (no descriptor taken then). Opened without following a symlink
    and without blocking (a FIFO put in its place is an OSError, not a hang); anything but a
    regular file is an OSError naming what it is."""
    try:
        if stamp(os.stat(path, follow_symlinks=False)) == seen:
            return None
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_NOFOLLOW | os.O_NOCTTY)
    except FileNotFoundError:
        return None
    status = os.fstat(fd)
    if not stat.S_ISREG(status.st_mode):
        os.close(fd)
        raise OSError(f"{path} is {kind_of(status.st_mode)}, not a regular file")
    with os.fdopen(fd, "rb") as fh:
        fh.seek(offset)
        return stamp(status), fh.read(max(status.st_size - offset, 0))
