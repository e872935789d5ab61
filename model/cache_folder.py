"""Whether a cache folder is this user's alone: one rule for every cache model/ reads back.

A cache that another user can write into can change what this user's next process computes
(a table multiplied by 100, a kernel replaced), so a folder holding one must be owned by the
effective user and writable by no group and nobody else. The rule covers the folder itself,
not its parents: a cache under a sticky, world-writable /tmp is fine, since only its owner
can rename or delete the folder there. Folders a cache creates are made 0700.
"""

from __future__ import annotations

import os
import stat
import warnings
from functools import cache
from pathlib import Path


def untrusted(folder: Path) -> str | None:
    """Why another user could change what `folder` holds (owned by another user, group- or
    world-writable), or None when it is this user's alone or does not exist."""
    try:
        status = os.stat(folder)
    except OSError:
        return None
    if status.st_uid != os.geteuid():
        return f"owned by uid {status.st_uid}, not {os.geteuid()}"
    for bit, who in ((stat.S_IWOTH, "world"), (stat.S_IWGRP, "group")):
        if status.st_mode & bit:
            return f"{who}-writable (mode {stat.S_IMODE(status.st_mode):04o})"
    return None


def made_private(folder: Path) -> str | None:
    """Create `folder` (mode 0700) unless it exists, then untrusted(folder); an OSError when
    the disk refuses to create it."""
    folder.mkdir(mode=0o700, exist_ok=True)
    return untrusted(folder)


@cache
def warn_untrusted(what: str, folder: str, reason: str) -> None:
    """One warning per cache folder and reason: `what` (the cache's name) is not used there."""
    warnings.warn(f"{what} in {folder} is not used: {reason}, so another user could change "
                  "what it holds; what this process builds stays in memory only",
                  RuntimeWarning, stacklevel=3)
