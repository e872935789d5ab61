"""HigherOrderLobe's walked planes kept on disk, so a bench's tables are walked once per machine.

A plane's build is a fixed function of the lobe's parameters, its walks and seed, and the code
that walks it, so a file named by a digest of all of these holds it for every later process:
an emulated bench with 2^24 walks per table pays minutes once, then milliseconds. Where:
$GONIO_CACHE_DIR, else $XDG_CACHE_HOME/gonio, else ~/.cache/gonio (GONIO_CACHE_DIR=off: none).
Each file carries a digest of its plane and of what the plane was built from (the lobe's
description, the code digest and the plane's address): a file that does not match it
(altered, truncated, corrupt, another shape) is walked again and replaced, with one warning
per folder, as is a file another user could have written (model.cache_folder's rule, checked
on the file itself: a folder that passes it now may hold what was planted before). A cache
folder another user could write into is not used, with one warning; neither is one that
refuses the file (read-only, disk full): the build stays in memory only.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
import warnings
from collections.abc import Mapping
from functools import cache, lru_cache
from pathlib import Path

import numpy as np

from model.cache_folder import (
    UntrustedFile,
    all_trusted,
    made_private,
    private_file,
    untrusted,
)

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
        self.built_from = json.dumps({**description, "code": code_digest()}, sort_keys=True)
        self.key = hashlib.blake2b(self.built_from.encode(), digest_size=16).hexdigest()
        self.root = root
        self.folder = root / SUBDIR
        self._private = False  # root and folder exist and are this user's alone
        self._refused = False  # one of them is not: the store is not used

    def path(self, address: tuple[int, ...]) -> Path:
        """The file of one plane: side, incidence node, plane, hemisphere."""
        return self.folder / f"{self.key}-{'-'.join(map(str, address))}.npz"

    def digest(self, address: tuple[int, ...], plane: np.ndarray) -> str:
        """What a plane's file carries: a digest of what the plane was built from (the lobe's
        description, the code digest, its address and shape) and of its values."""
        digest = hashlib.blake2b(digest_size=32)
        digest.update(json.dumps([self.built_from, address, plane.shape]).encode())
        digest.update(np.ascontiguousarray(plane, dtype=np.float64).tobytes())
        return digest.hexdigest()

    def load(self, address: tuple[int, ...], shape: tuple[int, ...]) -> np.ndarray | None:
        """The stored plane if its file matches its digest and shape, else None (a missing
        file silently, a damaged or altered one with one warning per folder): whatever a
        damaged file makes numpy raise or return is a miss."""
        if not self._usable(create=False):
            return None
        path = self.path(address)
        problem = MISMATCH
        try:
            stored = self._read(path, address)
        except FileNotFoundError:
            return None
        except UntrustedFile as exc:
            stored, problem = None, f"is not this user's alone ({exc})"
        except Exception:  # noqa: BLE001 - any unreadable file is a miss; the plane is walked
            stored = None
        if stored is None or stored.shape != shape:
            _warn_replaced(str(self.folder), problem)
            return None
        return stored

    def _read(self, path: Path, address: tuple[int, ...]) -> np.ndarray | None:
        """The plane in a file if the file is this user's alone (model.cache_folder) and holds
        a plane and its matching digest, else None."""
        with private_file(path) as handle:
            archive = np.load(handle, allow_pickle=False)
            if not isinstance(archive, np.lib.npyio.NpzFile):  # a bare array: no digest
                return None
            with archive:
                if sorted(archive.files) != ["digest", "plane"]:
                    return None
                plane, digest = archive["plane"], archive["digest"]
        if plane.dtype != np.float64 or digest.shape != () \
                or str(digest) != self.digest(address, plane):
            return None
        return plane

    def save(self, address: tuple[int, ...], plane: np.ndarray) -> bool:
        """Write a plane and its digest (a temporary file renamed into place, so a reader sees
        the whole file or none); False, leaving nothing behind, when the folder is not this
        user's alone or the disk refuses the file."""
        partial = None
        plane = np.ascontiguousarray(plane, dtype=np.float64)
        try:
            if not self._usable(create=True):
                return False
            with tempfile.NamedTemporaryFile(dir=self.folder, suffix=".partial",
                                             delete=False) as handle:
                partial = Path(handle.name)
                np.savez(handle, plane=plane, digest=np.array(self.digest(address, plane)))
            os.replace(partial, self.path(address))
            return True
        except OSError:
            return False
        finally:  # also on an interrupt: no partial file is left (after the rename there is none)
            if partial is not None:
                partial.unlink(missing_ok=True)

    def _usable(self, create: bool) -> bool:
        """Whether root and its planes' folder are this user's alone (created 0700 first when
        `create`; missing ones are fine to read from: they hold nothing). The first folder
        found wanting is warned about once and the store is not used again."""
        if self._private:
            return True
        if self._refused:
            return False
        if create:
            self.root.parent.mkdir(parents=True, exist_ok=True)
        if not all_trusted("gonio's table cache", (self.root, self.folder),
                           made_private if create else untrusted):
            self._refused = True
            return False
        self._private = self.folder.is_dir()
        return True


#: What a plane file that fails its digest (or cannot be read as one) is said to be.
MISMATCH = "does not match its digest (altered or damaged)"


@cache
def _warn_replaced(folder: str, problem: str) -> None:
    """One warning per folder and problem, however many of its planes have it."""
    warnings.warn(f"gonio's table cache in {folder}: a plane {problem}: walked again and "
                  "replaced, as is any other such plane there", RuntimeWarning, stacklevel=3)


def plane_store(description: Mapping[str, object]) -> PlaneStore | None:
    """The store for a lobe described so, in cache_root(); None when that is off."""
    root = cache_root()
    return None if root is None else PlaneStore(description, root)
