"""A file a user names (a config, a plan, a register map, a calibration, an imported
measurement), opened and read within bounds: a regular file of at most `cap` bytes, opened
without blocking, so that a FIFO, a device such as /dev/zero, a socket or a directory is one
error naming the file instead of a hang or an exhausted memory."""

from __future__ import annotations

import os
import stat
from pathlib import Path
from typing import BinaryIO

#: The most a settings file may hold (a config, a plan, a register map, a calibration): far
#: above any real one, far below what would exhaust memory when parsed.
SETTINGS_FILE_CAP = 4 * 2**20

#: What a file that is not a regular file is, by its stat mode.
KINDS = ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO"), (stat.S_ISSOCK, "a socket"),
         (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"))


def kind_of(mode: int) -> str:
    """What a file that is not a regular file is ("a FIFO", "a directory"), by its stat mode."""
    return next((name for test, name in KINDS if test(mode)), "not a regular file")


def open_user_file(path: str | Path, what: str, cap: int,
                   error: type[Exception]) -> BinaryIO:
    """The regular file `path` (a `what`: "plan", "register map") opened for reading, at most
    `cap` bytes long; otherwise `error` naming the file: missing, unreadable, not a regular
    file, or over the cap. Opening never blocks (O_NONBLOCK, cleared once it is known to be a
    regular file)."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_NOCTTY)
    except OSError as exc:
        raise error(f"{path}: cannot read {what} ({exc.strerror})") from None
    try:
        mode, size = (info := os.fstat(fd)).st_mode, info.st_size
        if not stat.S_ISREG(mode):
            raise error(f"{path}: {what} must be a regular file, not {kind_of(mode)}")
        if size > cap:
            raise error(f"{path}: {what} is {size} bytes, over the {cap}-byte limit")
        os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def read_user_file(path: str | Path, what: str, cap: int, error: type[Exception]) -> bytes:
    """The contents of the regular file `path` (open_user_file), reading at most cap + 1 bytes
    so that a file growing past the cap is refused too."""
    with open_user_file(path, what, cap, error) as fh:
        try:
            data = fh.read(cap + 1)
        except OSError as exc:
            raise error(f"{path}: cannot read {what} ({exc.strerror})") from None
    if len(data) > cap:
        raise error(f"{path}: {what} is over the {cap}-byte limit")
    return data


def read_user_text(path: str | Path, what: str, cap: int, error: type[Exception]) -> str:
    """read_user_file decoded as UTF-8 (`error` if it is not text)."""
    return user_text(read_user_file(path, what, cap, error), path, what, error)


def user_text(data: bytes, path: str | Path, what: str, error: type[Exception]) -> str:
    """The bytes of the user's file `path` (a `what`) decoded as UTF-8 (`error` if they are
    not text)."""
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        raise error(f"{path}: {what} is not a text file (UTF-8)") from None
