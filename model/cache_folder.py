"""Whether a cache folder is this user's alone: one rule for every cache model/ reads back.

A cache that another user can write into can change what this user's next process computes
(a table multiplied by 100, a kernel replaced), so a folder holding one must be owned by the
effective user and writable by no group and nobody else. The rule covers the folder itself,
not its parents: a cache under a sticky, world-writable /tmp is fine, since only its owner
can rename or delete the folder there. Folders a cache creates are made 0700. The files read
back from such a folder pass the same rule, each on its own descriptor.
"""

from __future__ import annotations

import errno
import os
import stat
import warnings
from collections.abc import Callable, Iterable
from functools import cache
from pathlib import Path
from typing import BinaryIO


class UntrustedFile(Exception):
    """A cache file that another user could have written; its message says why."""


def untrusted(folder: Path) -> str | None:
    """Why another user could change what `folder` holds (owned by another user, group- or
    world-writable), or None when it is this user's alone or does not exist."""
    try:
        status = os.stat(folder)
    except OSError:
        return None
    return _not_own(status)


def _not_own(status: os.stat_result) -> str | None:
    """The rule: why a file or folder of this status is not the effective user's alone."""
    if status.st_uid != os.geteuid():
        return f"owned by uid {status.st_uid}, not {os.geteuid()}"
    for bit, who in ((stat.S_IWOTH, "world"), (stat.S_IWGRP, "group")):
        if status.st_mode & bit:
            return f"{who}-writable (mode {stat.S_IMODE(status.st_mode):04o})"
    return None


def private_file(path: Path) -> BinaryIO:
    """The cache file `path` opened for reading if it is a regular file that is this user's
    alone (the rule above, checked on the descriptor that is read); UntrustedFile otherwise,
    a symbolic link included (never followed: it could point at any file). A missing file is
    FileNotFoundError. A folder passing the rule now may hold files another user planted
    while it did not."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_NOCTTY)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise UntrustedFile("a symbolic link") from None
        raise
    status = os.fstat(fd)
    reason = "not a regular file" if not stat.S_ISREG(status.st_mode) else _not_own(status)
    if reason is not None:
        os.close(fd)
        raise UntrustedFile(reason)
    return os.fdopen(fd, "rb")


def made_private(folder: Path) -> str | None:
    """Create `folder` (mode 0700) unless it exists, then untrusted(folder); an OSError when
    the disk refuses to create it."""
    folder.mkdir(mode=0o700, exist_ok=True)
    return untrusted(folder)


def all_trusted(what: str, folders: Iterable[Path],
                judge: Callable[[Path], str | None] = untrusted) -> bool:
    """Whether every folder passes `judge` (untrusted, or made_private to create them); the
    first that does not is warned about (warn_untrusted: `what` is the cache's name)."""
    for folder in folders:
        reason = judge(folder)
        if reason is not None:
            warn_untrusted(what, str(folder), reason)
            return False
    return True


@cache
def warn_untrusted(what: str, folder: str, reason: str) -> None:
    """One warning per cache folder and reason: `what` (the cache's name) is not used there."""
    warnings.warn(f"{what} in {folder} is not used: {reason}, so another user could change "
                  "what it holds; what this process builds stays in memory only",
                  RuntimeWarning, stacklevel=3)
