"""Numba's on-disk kernels kept true to the sources they were compiled from.

Numba drops a cached kernel when the kernel's own file changes, not when a file it calls into
or takes constants from does: an update that edits primitives.py alone left the random walk
on the old formulas (walk_kernel.py's cache was still valid). So every numba cache file under
model/ is dropped, once, when any source file under model/ differs from what the caches were
written with; numba recompiles on first use (tens of seconds once, then cached again).
A process started before an edit can still save a kernel compiled from the old sources after
another process kept the new digest (numba stamps it with its own, unchanged file): editing
while such a process compiles needs a second `import model` after it ends.

`compiled` is how model/ asks numba for a cached kernel: a cache file the disk refuses (full,
read-only, a file-size limit) is one warning per cache folder and the kernel stays in memory;
numba's own cache lets the write's OSError end the call that compiled it. A cache outside
the sources (NUMBA_CACHE_DIR, numba's user-wide one) in a folder another user could write into
(model.cache_folder's rule: numba's index files are pickles) is neither read nor written, with
one warning: kernels are compiled in memory. The sources' own __pycache__ is the install's:
whoever can write there can replace the bytecode Python imports from it.
"""

from __future__ import annotations

import hashlib
import os
import warnings
from collections.abc import Callable
from functools import cache
from pathlib import Path

from model.cache_folder import all_trusted

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


def compiled(**options: object) -> Callable[[Callable], Callable]:
    """numba.njit(cache=True, **options), its cache writes made non-fatal (module docstring)."""
    from numba import njit

    def decorate(function: Callable) -> Callable:
        dispatcher = njit(**options)(function)
        if hasattr(dispatcher, "enable_caching"):  # not a plain function (NUMBA_DISABLE_JIT)
            # what dispatcher.enable_caching() sets (njit(cache=True)), but tolerant
            dispatcher._cache = _tolerant_cache()(function)
        return dispatcher

    return decorate


@cache
def _tolerant_cache() -> type:
    """numba's FunctionCache, but a save the disk refuses warns instead of raising."""
    from numba.core.caching import FunctionCache, InTreeCacheLocator

    class TolerantCache(FunctionCache):
        """A kernel's cache whose refused write leaves the kernel in memory only, and which
        reads and writes nothing in a folder another user could write into."""

        def load_overload(self, sig, target_context) -> object:
            return super().load_overload(sig, target_context) if self._trusted() else None

        def save_overload(self, sig, data) -> None:
            if not self._trusted():
                return
            try:
                super().save_overload(sig, data)
            except OSError as exc:
                _warn_refused(self.cache_path, exc.strerror or str(exc))

        def _trusted(self) -> bool:
            """Whether the cache folder and the cache directory numba made it in are this
            user's alone; the source folder's own __pycache__ is the install's (whoever can
            write there can replace the bytecode Python imports from it)."""
            if isinstance(self._impl.locator, InTreeCacheLocator):
                return True
            folder = Path(self.cache_path)
            return all_trusted("numba's kernel cache", (folder, folder.parent))

    return TolerantCache


@cache
def _warn_refused(folder: str, reason: str) -> None:
    """One warning per cache folder and reason, however many kernels it refuses."""
    warnings.warn(f"numba's kernel cache in {folder} refused a write ({reason}): kernels "
                  "compiled by this process stay in memory only", RuntimeWarning, stacklevel=2)
