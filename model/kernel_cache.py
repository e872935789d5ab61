"""Numba's on-disk kernels kept true to the sources they were compiled from.

Numba drops a cached kernel when the kernel's own file changes, not when a file it calls into
or takes constants from does: an update that edits primitives.py alone left the random walk
on the old formulas (walk_kernel.py's cache was still valid). So every numba cache file under
model/ is dropped, once, when any source file under model/ differs from what the caches were
written with; numba recompiles on first use (tens of seconds once, then cached again).
A process started before an edit can still save a kernel compiled from the old sources after
another process kept the new digest (numba stamps it with its own, unchanged file): editing
while such a process compiles needs a second `import model` after it ends.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

ROOT = Path(__file__).resolve().parent
#: Where the sources' digest lives, beside numba's own cache files of this package.
STAMP = Path("__pycache__") / "kernel-sources.digest"
CACHE_SUFFIXES = (".nbi", ".nbc")


def sources_digest(root: Path = ROOT) -> str:
    """A digest of every .py file under root, names and contents."""
    digest = hashlib.blake2b(digest_size=16)
    for path in sorted(root.rglob("*.py")):
        digest.update(str(path.relative_to(root)).encode() + b"\0" + path.read_bytes() + b"\0")
    return digest.hexdigest()


def drop_stale_kernels(root: Path = ROOT) -> bool:
    """Delete root's numba cache files if the sources changed since they were written (or no
    digest was kept), then keep the new digest; True if it deleted. A read-only install
    changes nothing (numba then caches elsewhere, by its own stamps)."""
    stamp = root / STAMP
    now = sources_digest(root)
    try:
        if stamp.read_text() == now:
            return False
    except OSError:
        pass
    try:
        for path in root.rglob("*"):
            if path.suffix in CACHE_SUFFIXES and path.parent.name == "__pycache__":
                path.unlink(missing_ok=True)
        stamp.parent.mkdir(exist_ok=True)
        partial = stamp.with_name(f"{stamp.name}.{os.getpid()}")
        partial.write_text(now)
        partial.replace(stamp)
    except OSError:
        pass
    return True
