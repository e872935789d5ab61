"""libbsdf (KimuraRyo's library behind BSDF Processor) as the conformance suite's reader of
ASTM E1392 and Zemax tabular BSDF files: the library built from the unmodified snapshot in
`../shared/third_party/libbsdf` (GONIO_THIRD_PARTY overrides the folder) once per machine,
into a cache outside the checkout (GONIO_LIBBSDF_CACHE, default ~/.cache/gonio/libbsdf-<snapshot
commit>) under a file lock so that two xdist workers build it once, and this folder's
libbsdf_probe.cpp compiled against it: the values libbsdf returns at given directions."""

from __future__ import annotations

import fcntl
import hashlib
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
from third_party import third_party

PROBE_SOURCE = Path(__file__).with_name("libbsdf_probe.cpp")


class ReaderUnavailable(Exception):
    """libbsdf cannot be built here (no snapshot, or a tool missing: ToolMissing): the reason."""


class ToolMissing(ReaderUnavailable):
    """A tool the build needs (a C++ compiler, CMake, make, Eigen) is not installed."""


def snapshot_dir() -> Path:
    """The libbsdf snapshot (tests.conformance.third_party)."""
    return third_party("libbsdf")


def snapshot_commit(source: Path) -> str:
    """The commit its SNAPSHOT file names (`owner/name <commit> (date), ...`)."""
    try:
        return (source / "SNAPSHOT").read_text().split()[1]
    except (OSError, IndexError):
        raise ReaderUnavailable(f"{source}/SNAPSHOT names no commit") from None


def cache_dir(commit: str) -> Path:
    """Where the build of one snapshot lives."""
    explicit = os.environ.get("GONIO_LIBBSDF_CACHE")
    if explicit:
        return Path(explicit)
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / "gonio" / f"libbsdf-{commit[:12]}"


def _run(command: list[str], log: Path) -> None:
    """Run a build step, its output appended to `log`; a failure names the log."""
    with open(log, "a") as out:
        done = subprocess.run(command, stdout=out, stderr=subprocess.STDOUT, check=False)
    if done.returncode != 0:
        raise RuntimeError(f"libbsdf build step {command[0]} failed: see {log}")


def build_probe() -> Path:
    """The probe executable, building libbsdf (library only, make -j2) and the probe first
    where the cache lacks them; ReaderUnavailable (ToolMissing for a tool) says why it cannot
    be built here."""
    source = snapshot_dir()
    if not (source / "CMakeLists.txt").is_file():
        raise ReaderUnavailable(f"no libbsdf snapshot at {source} (set GONIO_THIRD_PARTY)")
    for tool in ("cmake", "make", "c++"):
        if shutil.which(tool) is None:
            raise ToolMissing(f"{tool} not found (apt-get install cmake g++ libeigen3-dev)")
    if not Path("/usr/include/eigen3/Eigen").is_dir():
        raise ToolMissing("Eigen 3 not found (apt-get install libeigen3-dev)")
    cache = cache_dir(snapshot_commit(source))
    cache.mkdir(parents=True, exist_ok=True)
    digest = hashlib.sha256(PROBE_SOURCE.read_bytes()).hexdigest()[:12]
    probe = cache / f"libbsdf_probe-{digest}"
    with open(cache / "build.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        library = cache / "build" / "liblibbsdf.a"
        log = cache / "build.log"
        if not library.is_file():
            _run(["cmake", "-S", str(source), "-B", str(cache / "build"),
                  "-DCMAKE_BUILD_TYPE=Release", "-DLIBBSDF_BUILD_APPLICATIONS=OFF",
                  "-DLIBBSDF_USE_OPENMP=OFF"], log)
            _run(["make", "-C", str(cache / "build"), "-j2", "libbsdf"], log)
        if not probe.is_file():
            _run(["c++", "-std=c++17", "-O2", "-msse3", f"-I{source / 'include'}",
                  "-I/usr/include/eigen3", str(PROBE_SOURCE), str(library), "-o",
                  str(probe)], log)
    return probe


def libbsdf_values(probe: Path, kind: str, path: Path, wi: np.ndarray, wo: np.ndarray
                   ) -> tuple[str, np.ndarray]:
    """(the data type libbsdf read, its values at the (N, 3) direction pairs in libbsdf's
    frame) of the file at `path`, read as `kind` (astm-brdf, astm-btdf or zemax)."""
    lines = "".join(" ".join(repr(float(x)) for x in (*a, *b)) + "\n"
                    for a, b in zip(wi, wo, strict=True))
    done = subprocess.run([str(probe), kind, str(path)], input=lines, capture_output=True,
                          text=True, check=False)
    if done.returncode != 0:
        raise AssertionError(f"libbsdf could not read {path}: {done.stderr.strip()}")
    words = [ln.split() for ln in done.stdout.splitlines()]
    kind_read = next(w[1] for w in words if len(w) == 2 and w[0] == "type")
    values = np.array([float(w[1]) for w in words if len(w) == 2 and w[0] == "value"])
    assert len(values) == len(wi), f"libbsdf_probe returned {len(values)} of {len(wi)} values"
    return kind_read, values
