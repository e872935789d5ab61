"""Heitz et al.'s published C++ random walk, built and timed for bench/multiple_scattering.py.

Its source (MicrosurfaceScattering.cpp and .h as released with "Multiple-scattering microfacet
BSDFs with the Smith model", 2016; no licence stated, so never part of gonio) comes from a
folder the user names (--cpp-source DIR, or GONIO_HEITZ_SOURCE); the driver that times it
(heitz_walk/driver.cpp) and the few GLM operations it needs (heitz_walk/glm, used where no GLM
is installed) are gonio's. Built with g++ -O2 once per source, driver and compiler, and kept
under ~/.cache/gonio/heitz-walk/.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
from pathlib import Path

SOURCE_ENV = "GONIO_HEITZ_SOURCE"
SOURCE_FILES = ("MicrosurfaceScattering.cpp", "MicrosurfaceScattering.h")
DRIVER = Path(__file__).resolve().parent / "heitz_walk"
DRIVER_FILES = (DRIVER / "driver.cpp", DRIVER / "glm" / "glm.hpp")
FLAGS = ("-O2", "-std=c++17")


def source_folder(given: str | None) -> Path | None:
    """The folder holding the C++ source (given, else $GONIO_HEITZ_SOURCE), or None; a folder
    without both files is one clear error."""
    folder = given or os.environ.get(SOURCE_ENV)
    if not folder:
        return None
    path = Path(folder).expanduser()
    missing = [name for name in SOURCE_FILES if not (path / name).is_file()]
    if missing:
        raise SystemExit(f"C++ walk source {path}: no {' or '.join(missing)} there")
    return path


def _cache() -> Path:
    return Path(os.environ.get("XDG_CACHE_HOME", "~/.cache")).expanduser() / "gonio" / "heitz-walk"


def build(source: Path) -> Path:
    """The driver linked with the source at `source`, compiled if this source, driver and
    compiler have not been built before."""
    compiler = shutil.which("g++")
    if compiler is None:
        raise SystemExit("building Heitz et al.'s C++ walk needs g++ on the PATH")
    version = subprocess.run([compiler, "--version"], capture_output=True, text=True,
                             check=True).stdout.splitlines()[0]
    digest = hashlib.blake2b(digest_size=12)
    for path in (*(source / name for name in SOURCE_FILES), *DRIVER_FILES):
        digest.update(path.read_bytes() + b"\0")
    digest.update(" ".join((version, *FLAGS)).encode())
    binary = _cache() / digest.hexdigest() / "heitz-walk"
    if binary.is_file():
        return binary
    binary.parent.mkdir(parents=True, exist_ok=True)
    partial = binary.with_suffix(".partial")
    done = subprocess.run([compiler, *FLAGS, "-I", str(source), "-idirafter", str(DRIVER),
                           str(source / SOURCE_FILES[0]), str(DRIVER_FILES[0]), "-o",
                           str(partial)], capture_output=True, text=True)
    if done.returncode:
        raise SystemExit(f"g++ could not build the C++ walk from {source}:\n{done.stderr[-2000:]}")
    partial.replace(binary)
    return binary


def walks_per_cpu_second(binary: Path, distribution: str, kind: str, alpha: float,
                         theta_deg: float, mode: str, walks: int) -> tuple[float, float, float]:
    """(walks per CPU-second, mean wo_z, share of wo below the surface) of `walks` sample walks
    (mode "sample"; "eval": per eval walk, the albedo estimate instead of the two means) from
    theta_deg, as the driver reports them (CLOCK_PROCESS_CPUTIME_ID over the walks alone)."""
    done = subprocess.run([str(binary), distribution, kind, repr(float(alpha)),
                           repr(float(theta_deg)), mode, str(int(walks))],
                          capture_output=True, text=True, check=True)
    rate, first, second = (float(v) for v in done.stdout.split())
    return rate, first, second
