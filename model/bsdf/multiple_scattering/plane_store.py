"""HigherOrderLobe's walked planes kept on disk, so a bench's tables are walked once per machine.

A plane's build is a fixed function of the lobe's parameters, its walks and seed, and the code
that walks it, so a file named by a digest of all of these holds it for every later process:
an emulated bench with 2^24 walks per table pays minutes once, then milliseconds. Where:
$GONIO_CACHE_DIR, else $XDG_CACHE_HOME/gonio, else ~/.cache/gonio (GONIO_CACHE_DIR=off: none).
A file that cannot be read back whole (truncated, corrupt, another shape) is walked again and
replaced; one that cannot be written (read-only, disk full) leaves the build in memory only.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from collections.abc import Mapping
from functools import lru_cache
from pathlib import Path

import numpy as np

#: The subdirectory of the cache directory that holds the planes.
SUBDIR = "ms-planes"
#: GONIO_CACHE_DIR values that turn the store off.
OFF = ("", "0", "off", "none")


def cache_root() -> Path | None:
    """The cache directory ($GONIO_CACHE_DIR, $XDG_CACHE_HOME/gonio, ~/.cache/gonio), or None
    when GONIO_CACHE_DIR turns it off or no home directory can be found (no HOME and no passwd
    entry, as in a container run as an unknown user)."""
    chosen = os.environ.get("GONIO_CACHE_DIR")
    xdg = os.environ.get("XDG_CACHE_HOME")
    try:
        if chosen is not None:
            return None if chosen.strip().lower() in OFF else Path(chosen).expanduser()
        if xdg and Path(xdg).is_absolute():  # the XDG spec ignores a relative one
            return Path(xdg) / "gonio"
        return Path.home() / ".cache" / "gonio"
    except (RuntimeError, KeyError):
        return None


@lru_cache(maxsize=1)
def code_digest() -> str:
    """What the walked values depend on besides their parameters: every source file of
    model.bsdf (the walks, order 2's quadrature, the facets) and the numpy, scipy (the tables'
    PCHIP slopes) and numba versions."""
    import scipy

    from model.kernel_cache import sources_digest

    try:
        import numba
        numba_version = numba.__version__
    except ImportError:
        numba_version = "none"
    root = Path(__file__).resolve().parents[1]
    return f"{sources_digest(root)}-{np.__version__}-{scipy.__version__}-{numba_version}"


class PlaneStore:
    """Files of one lobe's planes under root, named by a digest of `description` (everything
    the lobe's values depend on: HigherOrderLobe gives its parent's parameters, its walks,
    seed and grid) and code_digest(). Files of earlier code stay until deleted (a few kB a
    plane)."""

    def __init__(self, description: Mapping[str, object], root: Path):
        text = json.dumps({**description, "code": code_digest()}, sort_keys=True)
        self.key = hashlib.blake2b(text.encode(), digest_size=16).hexdigest()
        self.folder = root / SUBDIR

    def path(self, address: tuple[int, ...]) -> Path:
        """The file of one plane: side, incidence node, plane, hemisphere."""
        return self.folder / f"{self.key}-{'-'.join(map(str, address))}.npy"

    def load(self, address: tuple[int, ...], shape: tuple[int, ...]) -> np.ndarray | None:
        """The stored plane if it is whole (a float64 array of this shape, finite), else None:
        whatever a damaged file makes numpy raise or return is a miss."""
        try:
            stored = np.load(self.path(address), allow_pickle=False)
        except Exception:  # noqa: BLE001 - any unreadable file is a miss; the plane is walked
            return None
        if not isinstance(stored, np.ndarray):  # a zip archive (np.load gives an NpzFile)
            stored.close()
            return None
        if stored.dtype != np.float64 or stored.shape != shape or not np.all(np.isfinite(stored)):
            return None
        return stored

    def save(self, address: tuple[int, ...], plane: np.ndarray) -> bool:
        """Write a plane (a temporary file renamed into place, so a reader sees the whole file
        or none); False, leaving nothing behind, when the disk refuses it."""
        partial = None
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
            with tempfile.NamedTemporaryFile(dir=self.folder, suffix=".partial",
                                             delete=False) as handle:
                partial = Path(handle.name)
                np.save(handle, np.ascontiguousarray(plane, dtype=np.float64))
            os.replace(partial, self.path(address))
            return True
        except OSError:
            return False
        finally:  # also on an interrupt: no partial file is left (after the rename there is none)
            if partial is not None:
                partial.unlink(missing_ok=True)


def plane_store(description: Mapping[str, object]) -> PlaneStore | None:
    """The store for a lobe described so, in cache_root(); None when that is off."""
    root = cache_root()
    return None if root is None else PlaneStore(description, root)
