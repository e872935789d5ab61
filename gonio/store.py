"""The run store: one directory per run, readings appended and fsynced one line at a time.

Layout of a run directory:

    plan.toml, instrument.toml   verbatim copies of the files the run was started from
    plan.json, config.json       the parsed plan and config the run uses (resume reads these)
    meta.json                    versions, seeds, sim devices, calibration, sessions, status
    readings.jsonl               one JSON object per reading, appended and fsynced in order

A run killed at any moment keeps every completed line; a torn last line (no newline or not
JSON) is ignored when reading and cut off when the run is resumed.

Each reading's line is written to the file at once (so a killed process never loses it) and
then fsynced on a helper thread while the engine goes on to the next point; the next line is
written only after that fsync has returned, so at most one line is on its way to the disk,
lines reach it in order, and whatever the writer reports as stored (meta.json, the final
count) has been fsynced.
"""

from __future__ import annotations

import fcntl
import json
import os
import platform
import re
import shutil
import sys
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

from gonio.errors import RunError

READINGS = "readings.jsonl"
META = "meta.json"

READING_DTYPE = np.dtype([
    ("index", "i8"), ("kind", "U12"), ("side", "U12"), ("repeat", "i4"), ("point", "i8"),
    ("sample_deg", "f8"), ("arm_deg", "f8"), ("azimuth_deg", "f8"), ("elevation_deg", "f8"),
    ("theta_i_deg", "f8"), ("phi_i_deg", "f8"), ("theta_o_deg", "f8"), ("phi_o_deg", "f8"),
    ("plan_theta_i_deg", "f8"), ("plan_theta_o_deg", "f8"), ("plan_phi_o_deg", "f8"),
    ("power_w", "f8"), ("range_w", "f8"), ("saturated", "?"), ("t_s", "f8"), ("flags", "U64"),
])
"""Fields of `Run.readings()`: angles in degrees (stage angles as the stages reported them,
sample-frame spherical angles computed from those; plan_* the nominal plan angles, NaN for
dark and beam readings), power and range in W, t_s seconds since
the run's first start (wall clock), flags a comma-separated list (e.g. "retried")."""


def utc_now() -> str:
    """Current UTC time, ISO 8601."""
    return datetime.now(timezone.utc).isoformat(timespec="milliseconds")


def _fsync_dir(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def write_json_atomic(path: Path, data: Any) -> None:
    """Write JSON via a temporary file, fsync and rename: never a half-written file."""
    tmp = path.with_suffix(path.suffix + ".tmp")
    with open(tmp, "w") as fh:
        json.dump(data, fh, indent=2, default=_json_default)
        fh.write("\n")
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)
    _fsync_dir(path.parent)


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"cannot store {type(obj).__name__} in JSON")


def _parse_lines(data: bytes) -> tuple[list[dict[str, Any]], int]:
    """Complete, valid JSON lines and the byte length they cover (a torn tail is left out)."""
    rows, good = [], 0
    for line in data.splitlines(keepends=True):
        if not line.endswith(b"\n"):
            break
        try:
            row = json.loads(line)
        except ValueError:
            break
        if not isinstance(row, dict) or row.get("index") != len(rows):
            break
        rows.append(row)
        good += len(line)
    return rows, good


def _locked(path: Path) -> Any:
    """Open the readings file for appending with an exclusive lock (released when the
    process ends, even by SIGKILL): two processes can never write one run."""
    fh = open(path, "ab")
    try:
        fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        fh.close()
        raise RunError(f"{path.parent}: the run is in use by another gonio process") from None
    return fh


@dataclass
class Run:
    """A run directory opened for reading (see `open_run`)."""

    path: Path
    plan: dict[str, Any]
    config: dict[str, Any]
    meta: dict[str, Any]

    def rows(self) -> list[dict[str, Any]]:
        """The complete readings as dicts, in order (a torn last line is ignored)."""
        return _parse_lines((self.path / READINGS).read_bytes())[0]

    def readings(self) -> np.ndarray:
        """The readings as a numpy structured array with READING_DTYPE fields."""
        rows = self.rows()
        out = np.zeros(len(rows), READING_DTYPE)
        for name in READING_DTYPE.names:
            if rows:
                out[name] = [_value(r.get(name)) for r in rows]
        return out

    def __len__(self) -> int:
        return len(self.rows())

    @property
    def status(self) -> str:
        """created | running | paused | completed | aborted | failed ("running" after a kill)."""
        return self.meta.get("status", "unknown")


def _value(v: Any) -> Any:
    return np.nan if v is None else v


def open_run(path: str | Path) -> Run:
    """Open a run directory for reading; RunError if it is not one."""
    path = Path(path)
    try:
        meta = json.loads((path / META).read_text())
        plan = json.loads((path / "plan.json").read_text())
        config = json.loads((path / "config.json").read_text())
    except FileNotFoundError as exc:
        raise RunError(f"{path}: not a run directory (missing {Path(exc.filename).name})") from None
    except (OSError, ValueError) as exc:
        raise RunError(f"{path}: damaged run directory ({exc})") from None
    if not (path / READINGS).exists():
        raise RunError(f"{path}: not a run directory (missing {READINGS})")
    return Run(path, plan, config, meta)


def versions() -> dict[str, str]:
    """Versions of what a run depends on, for its metadata."""
    from importlib import metadata

    out = {"python": sys.version.split()[0], "platform": platform.platform(),
           "numpy": np.__version__}
    for dist in ("gonio", "pyserial", "pymodbus"):
        try:
            out[dist] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            out[dist] = "not installed"
    return out


class RunWriter:
    """Appends readings to a run directory, one fsynced line each, and keeps meta.json."""

    def __init__(self, path: Path, meta: dict[str, Any], next_index: int):
        self.path = path
        self.meta = meta
        self.next_index = next_index
        self._fh = _locked(path / READINGS)
        self._syncer: ThreadPoolExecutor | None = None  # started by the first append
        self._pending: Future | None = None  # the fsync of the last line written

    @classmethod
    def create(cls, root: Path, name: str, plan_file: Path | None, config_file: Path | None,
               plan: dict[str, Any], config: dict[str, Any], meta: dict[str, Any]) -> RunWriter:
        """Make a new run directory under root (name + UTC timestamp, unique)."""
        root.mkdir(parents=True, exist_ok=True)
        stamp = datetime.now(timezone.utc).strftime("%Y%m%dT%H%M%SZ")
        name = re.sub(r"[^A-Za-z0-9._-]", "_", name)[:60].lstrip(".") or "run"
        for n in range(1000):
            path = root / (f"{stamp}-{name}" + (f"-{n}" if n else ""))
            try:
                path.mkdir()
                break
            except FileExistsError:
                continue
        else:
            raise RunError(f"{root}: cannot make a new run directory")
        for src, dest in ((plan_file, "plan.toml"), (config_file, "instrument.toml")):
            if src is not None:
                shutil.copyfile(src, path / dest)
        write_json_atomic(path / "plan.json", plan)
        write_json_atomic(path / "config.json", config)
        (path / READINGS).touch()
        meta = {**meta, "created_utc": utc_now(), "versions": versions(), "sessions": [],
                "status": "created", "reason": ""}
        write_json_atomic(path / META, meta)
        return cls(path, meta, 0)

    @classmethod
    def resume(cls, path: Path) -> RunWriter:
        """Reopen a run to continue it: cut a torn last line, continue after the last reading."""
        run = open_run(path)
        if run.status == "completed":
            raise RunError(f"{path}: run already completed; nothing to resume")
        writer = cls(path, run.meta, 0)  # takes the lock before touching the file
        data = (path / READINGS).read_bytes()
        rows, good = _parse_lines(data)
        if good < len(data):
            writer._fh.truncate(good)
            writer._fh.flush()
            os.fsync(writer._fh.fileno())
        writer.next_index = len(rows)
        return writer

    def start_session(self, **info: Any) -> None:
        """Record that a (new or resumed) session starts now."""
        self.meta["sessions"].append({"start_utc": utc_now(), "first_index": self.next_index,
                                      **info})
        self.meta.setdefault("started_utc", self.meta["sessions"][0]["start_utc"])
        self.set_status("running", "")

    def set_status(self, status: str, reason: str) -> None:
        """Update status and reason in meta.json (atomically), once every reading is stored."""
        self.wait_stored()
        self.meta["status"], self.meta["reason"] = status, reason
        if status != "running":
            self.meta["stopped_utc"] = utc_now()
            if self.meta["sessions"]:
                self.meta["sessions"][-1].update(stop_utc=self.meta["stopped_utc"],
                                                 status=status, last_index=self.next_index - 1)
        write_json_atomic(self.path / META, self.meta)

    def append(self, row: dict[str, Any]) -> None:
        """Write one reading (its index must be the next one) and start its fsync, once the
        previous reading's fsync has returned (see the module docstring)."""
        if row["index"] != self.next_index:
            raise RunError(f"{self.path}: reading {row['index']} out of order "
                           f"(expected {self.next_index})")
        clean = {k: None if isinstance(v, float) and v != v else v for k, v in row.items()}
        line = json.dumps(clean, default=_json_default).encode() + b"\n"  # +-inf: Infinity
        self.wait_stored()
        self._fh.write(line)
        self._fh.flush()  # in the kernel's hands: a killed process no longer loses it
        self.next_index += 1
        if self._syncer is None:
            self._syncer = ThreadPoolExecutor(1, thread_name_prefix="run-fsync")
        self._pending = self._syncer.submit(os.fsync, self._fh.fileno())

    def wait_stored(self) -> None:
        """Return once every appended reading is fsynced (OSError, once, if the disk refused).
        Interrupted (Ctrl-C), the fsync stays pending: the next call waits for it again."""
        pending = self._pending
        if pending is None:
            return
        try:
            pending.result()
        finally:
            if pending.done():
                self._pending = None

    def close(self) -> None:
        """Wait for the last fsync, then close the readings file."""
        try:
            self.wait_stored()
        finally:
            if self._syncer is not None:
                self._syncer.shutdown()
            self._fh.close()
