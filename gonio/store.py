"""The run store: one directory per run, readings appended and fsynced one line at a time.

Layout of a run directory:

    plan.toml, instrument.toml   verbatim copies of the files the run was started from
    plan.json, config.json       the parsed plan and config the run uses (resume reads these)
    meta.json                    versions, seeds, sim devices, calibration, sessions, status
    readings.jsonl               one JSON object per reading, appended and fsynced in order

Each line carries the run's identity (`run`: meta.json's `run_uid`) and a `crc32` field over
its canonical JSON without it, so a line copied from another run fails as surely as an edited
one; meta.json's `line_checksum` names the scheme (`crc32+run`; `crc32`, lines without the
run's identity, is an older one still read). A run killed at any moment keeps every
completed line; a torn last line (the bytes after the last newline: a half-written line, or
the NUL padding a power loss leaves) is ignored when reading and cut off when the run is
resumed. Any other damaged line (not JSON, a bad checksum, another run's line, a duplicated or
out-of-order index, missing indices), and any breach of the rules gonio.run_rules adds
(meta.json names its line checksum, the run's counts and sessions agree with its lines,
plan.json, config.json and the register maps match their digests) is an error for every reader
(one line; `open_run(path, force=True)` reads the valid readings and names what it read past)
and for resume: `gonio check RUN` reports it and `--repair` writes a copy that resume can
complete. Readings a run records as stored that its file no longer holds (a cut file) are
measured again by resume.

Each reading's line is written to the file at once (so a killed process never loses it) and
then fsynced on a helper thread while the engine goes on to the next point; the next line is
written only after that fsync has returned, so at most one line is on its way to the disk,
lines reach it in order, and whatever the writer reports as stored (meta.json, the final
count) has been fsynced.

A disk that refuses a write (full, a file-size limit, an I/O error) is a StoreError naming the
file: a new run directory is made whole or not at all (in a hidden folder of the root, then
renamed into place), and a line the disk cut short is a torn last line, cut on resume. Each
run keeps a small `.reserve` file that a full disk frees, so that meta.json can still record
why the run failed; resume makes it again.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import functools
import hashlib
import json
import os
import platform
import re
import secrets
import shutil
import sys
import zlib
from collections.abc import Collection, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from drivers.user_file import SETTINGS_FILE_CAP, read_user_file
from gonio.errors import RunError
from gonio.run_rules import (
    CRC,
    LINE_CHECKSUM,
    LINE_CHECKSUMS,
    RUN_UID,
    describe_indices,
    lost_and_session_problems,
    lost_indices,
    meta_problems,
    recorded_top,
    session_problems,
)

READINGS = "readings.jsonl"
META = "meta.json"
RESERVE, RESERVE_BYTES = ".reserve", 65536  # room kept for meta.json on a full disk
PARTIAL = ".partial"  # under a run root: run directories being made
RUN_FIELD = "run"  # a line's run identity (meta.json's RUN_UID)

READING_DTYPE = np.dtype([
    ("index", "i8"), ("kind", object), ("side", object), ("repeat", "i4"), ("point", "i8"),
    ("sample_deg", "f8"), ("arm_deg", "f8"), ("azimuth_deg", "f8"), ("elevation_deg", "f8"),
    ("theta_i_deg", "f8"), ("phi_i_deg", "f8"), ("theta_o_deg", "f8"), ("phi_o_deg", "f8"),
    ("plan_theta_i_deg", "f8"), ("plan_theta_o_deg", "f8"), ("plan_phi_o_deg", "f8"),
    ("power_w", "f8"), ("range_w", "f8"), ("saturated", "?"), ("t_s", "f8"), ("flags", object),
])
"""Fields of `Run.readings()`: angles in degrees (stage angles as the stages reported them,
sample-frame spherical angles computed from those; plan_* the nominal plan angles, NaN for
dark and beam readings), power and range in W, t_s seconds since
the run's first start (wall clock), flags a comma-separated list (e.g. "retried"). kind, side and
flags are Python strings (object fields), so no name is cut to a fixed width; "" where a line
has none."""


def utc_now() -> str:
    """Current UTC time, ISO 8601."""
    return datetime.now(UTC).isoformat(timespec="milliseconds")


def fsync_dir(path: Path) -> None:
    """fsync a directory (so a rename or a new file in it survives a power loss)."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def write_json_atomic(path: Path, data: Any) -> None:
    """Write JSON atomically (see `write_text_atomic`)."""
    write_text_atomic(path, json.dumps(data, indent=2, default=_json_default) + "\n")


def write_text_atomic(path: Path, text: str) -> None:
    """Write a text file via a temporary file, fsync and rename: never a half-written file
    (nor a temporary one left behind when the disk refuses)."""
    tmp = path.with_suffix(path.suffix + ".tmp")
    try:
        with open(tmp, "w", encoding="utf-8") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    fsync_dir(path.parent)


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"cannot store {type(obj).__name__} in JSON")


class DamagedRunError(RunError):
    """A run directory's files are damaged (not merely missing or in use)."""


class StoreError(RunError):
    """The disk refused a write to a run (full, a file-size limit, read-only, an I/O error)."""


def canonical_json(data: Any) -> bytes:
    """The JSON that checksums and digests are computed over: sorted keys, no spaces."""
    return json.dumps(data, sort_keys=True, separators=(",", ":"),
                      default=_json_default).encode()


def encode_line(row: dict[str, Any], checksum: bool = True, run_uid: str | None = None) -> bytes:
    """A reading's line: JSON (NaN as null, +-inf as Infinity) with the run's identity (if
    `run_uid`) and its crc32 last, and a newline."""
    clean = {k: None if isinstance(v, float) and v != v else v for k, v in row.items()}
    if run_uid is not None:
        clean[RUN_FIELD] = run_uid
    if checksum:
        clean[CRC] = zlib.crc32(canonical_json(clean))
    return json.dumps(clean, default=_json_default).encode() + b"\n"


@dataclass
class Damage:
    """A damaged line of readings.jsonl: its number (from 1) and what is wrong (a valid line
    that follows missing indices is kept as a reading but still reported)."""

    line: int
    problem: str


@dataclass
class Lines:
    """What readings.jsonl holds: the valid readings (by index), the damage, the torn tail."""

    rows: list[dict[str, Any]]
    damaged: list[Damage]
    keep_bytes: int  # up to the last newline: what resume keeps
    torn_bytes: int  # after it: a torn last line, cut on resume
    unchecked: int  # valid lines without a checksum (written before line checksums)
    count: int  # complete lines

    @property
    def top(self) -> int:
        """The highest stored index (-1 for none)."""
        return self.rows[-1]["index"] if self.rows else -1

    def missing(self) -> list[int]:
        """Indices below the highest stored one that are not stored."""
        present = {r["index"] for r in self.rows}
        return [i for i in range(self.top + 1) if i not in present]


def _check_line(line: bytes, checked: bool, run_uid: str | None
                ) -> tuple[dict[str, Any] | None, str, bool]:
    """The reading of one complete line and "", or None and what is wrong with it; and
    whether the line carried a checksum. `run_uid`: the run the line must say it belongs to
    (None: not checked)."""
    try:
        row = json.loads(line)
    except ValueError:
        return None, "NUL bytes" if b"\0" in line else ("empty line" if not line.strip()
                                                        else "not JSON"), False
    if not isinstance(row, dict):
        return None, "not a JSON object", False
    crc = row.pop(CRC, None)
    index = row.get("index")
    at = f" (index {index})" if isinstance(index, int) else ""
    if crc is None and checked:
        return None, f"no {CRC} checksum{at}", False
    if crc is not None and crc != zlib.crc32(canonical_json(row)):
        return None, f"{CRC} checksum mismatch{at}", True
    if not isinstance(index, int) or isinstance(index, bool) or index < 0:
        return None, "no valid index", crc is not None
    run = row.pop(RUN_FIELD, None)
    if run_uid is not None and run != run_uid:
        said = "no run identity" if run is None else f"a line of run {run}, not of this run"
        return None, f"{said} ({RUN_UID} {run_uid}){at}", True
    return row, "", crc is not None


class LineChecker:
    """Checks the complete lines of readings.jsonl in order as they come, keeping what it has
    seen: `scan_lines` feeds it a whole file, a viewer following a run another process writes
    feeds it each new stretch (the rules of `scan_lines`)."""

    def __init__(self, checked: bool, refill: Collection[int] = (), run_uid: str | None = None):
        self.checked, self.refill, self.run_uid = checked, refill, run_uid
        self.rows: dict[int, dict[str, Any]] = {}  # valid readings by index
        self.damaged: list[Damage] = []
        self.count = 0  # complete lines seen
        self.unchecked = 0
        self._where: dict[int, int] = {}
        self._top, self._since_valid = -1, 0

    def feed(self, complete: bytes) -> list[dict[str, Any]]:
        """Check the next complete lines (bytes that end with a newline, or none); returns the
        valid readings among them, in file order. A valid line out of order is damage, and
        still a reading (a repair keeps it)."""
        new = []
        for line in complete.split(b"\n")[:-1]:
            self.count += 1
            row, problem, has_crc = _check_line(line, self.checked, self.run_uid)
            if row is not None:
                index = row["index"]
                gap = [i for i in range(self._top + 1, index) if i not in self.refill]
                if index in self.rows:
                    problem, row = f"duplicate of index {index} (line {self._where[index]})", None
                elif index < self._top and index not in self.refill:
                    problem = f"index {index} out of order (after index {self._top})"
                elif len(gap) > self._since_valid:
                    self.damaged.append(Damage(self.count, f"index {index} follows index "
                                                           f"{self._top}: "
                                                           f"{describe_indices(gap)} missing"))
            if problem:
                self.damaged.append(Damage(self.count, problem))
                self._since_valid += 1
                if row is None:
                    continue
                self.rows[row["index"]], self._where[row["index"]] = row, self.count
                self.unchecked += not has_crc
                new.append(row)
                continue
            self.rows[index], self._where[index], self._since_valid = row, self.count, 0
            self._top = max(self._top, index)
            self.unchecked += not has_crc
            new.append(row)
        return new

    def lines(self, keep_bytes: int, torn_bytes: int) -> Lines:
        """What the lines fed so far hold (`keep_bytes` of them, `torn_bytes` after)."""
        return Lines([self.rows[i] for i in sorted(self.rows)], self.damaged, keep_bytes,
                     torn_bytes, self.unchecked, self.count)


def scan_lines(data: bytes, checked: bool, refill: Collection[int] = (),
               run_uid: str | None = None) -> Lines:
    """Check every complete line of readings.jsonl (JSON object, checksum if `checked` or
    present, the run's identity if `run_uid`, index neither repeated nor out of order, no
    indices missing unless damaged lines account for them). `refill`: indices a repair
    dropped, which may come later, out of order."""
    keep = data.rfind(b"\n") + 1
    checker = LineChecker(checked, refill, run_uid)
    checker.feed(data[:keep])
    return checker.lines(keep, len(data) - keep)


def damage_message(path: Path, lines: Lines, problems: Sequence[str] = (),
                   resume: bool = False) -> str:
    """One line: the first damaged line (else the first of the run's other `problems`), how
    many more, and what to do about it."""
    if lines.damaged:
        first, more = lines.damaged[0], len(lines.damaged) - 1
        text = (f"{path / READINGS} line {first.line}: {first.problem}"
                + (f" (and {more} more damaged line{'s' * (more > 1)})" if more else ""))
        others = len(problems)
    else:
        text, others = f"{path}: {problems[0]}", len(problems) - 1
    if others:
        text += f" (and {others} more problem{'s' * (others > 1)})"
    if resume:
        return (f"{text}; cannot resume: `gonio check {path} --repair OUT_DIR` writes a "
                f"repaired copy to resume instead")
    return f"{text}; `gonio check {path}` reports the damage, --force reads past it"


def damage_list(lines: Lines, problems: Sequence[str], most: int = 5) -> list[str]:
    """The damage, one entry each (the first `most` damaged lines, then how many more): what
    an output read with --force says it read past."""
    out = [f"{READINGS} line {d.line}: {d.problem}" for d in lines.damaged[:most]]
    if len(lines.damaged) > most:
        out.append(f"{READINGS}: {len(lines.damaged) - most} more damaged lines")
    return out + list(problems)


def digest(data: Any) -> str:
    """sha256 of a JSON value's canonical form."""
    return "sha256:" + hashlib.sha256(canonical_json(data)).hexdigest()


def map_digests(config: dict[str, Any]) -> dict[str, str | None]:
    """sha256 of each device's register-map file contents (None: the file is not there, or is
    not a regular file of bounded size: drivers.user_file, so a FIFO put in its place never
    blocks a check)."""
    out: dict[str, str | None] = {}
    for name, dev in config.get("devices", {}).items():
        if isinstance(dev, dict) and "register_map" in dev:
            try:
                data = read_user_file(dev["register_map"], "register map", SETTINGS_FILE_CAP,
                                      OSError)
            except OSError:
                out[name] = None
            else:
                out[name] = "sha256:" + hashlib.sha256(data).hexdigest()
    return out


def digests(plan: dict[str, Any], config: dict[str, Any]) -> dict[str, Any]:
    """What meta.json records at the start: digests of plan.json, config.json and the
    register maps' contents (not their paths: a moved checkout still resumes)."""
    return {"plan.json": digest(plan), "config.json": digest(config),
            "register_maps": map_digests(config)}


def digest_problems(run: Run, config: dict[str, Any] | None = None) -> list[str]:
    """How plan.json, config.json and the register maps of `config` (default: the run's)
    differ from the digests recorded at the start ([] for a run that recorded none:
    gonio.run_rules.meta_problems names that)."""
    recorded = run.meta.get("digests")
    if not recorded:
        return []
    problems = [f"{name} changed since the run started (its digest differs)"
                for name, data in (("plan.json", run.plan), ("config.json", run.config))
                if digest(data) != recorded.get(name)]
    now = map_digests(run.config if config is None else config)
    for name, was in recorded.get("register_maps", {}).items():
        if now.get(name, was) is None:
            problems.append(f"the register map of device {name!r} is not found, cannot check it")
        elif now.get(name, was) != was:
            problems.append(f"the register map of device {name!r} differs in content from "
                            f"the one the run started with")
    return problems


def _locked(path: Path) -> Any:
    """Open the readings file for appending with an exclusive lock (released when the
    process ends, even by SIGKILL): two processes can never write one run."""
    fh = open(path, "ab", buffering=0)  # unbuffered: a refused write keeps nothing back
    try:
        fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        fh.close()
        raise RunError(f"{path.parent}: the run is in use by another gonio process") from None
    return fh


@dataclass
class Run:
    """A run directory opened for reading (see `open_run`); `force`: read a damaged run's
    valid readings (`read_past` names the damage) instead of refusing it."""

    path: Path
    plan: dict[str, Any]
    config: dict[str, Any]
    meta: dict[str, Any]
    force: bool = False

    def lines(self) -> Lines:
        """Every line of readings.jsonl checked (see `scan_lines`)."""
        return scan_lines((self.path / READINGS).read_bytes(), **self._line_rules())

    def line_checker(self) -> LineChecker:
        """A LineChecker with this run's rules, to check its lines as they come."""
        return LineChecker(**self._line_rules())

    def _line_rules(self) -> dict[str, Any]:
        scheme = self.meta.get("line_checksum")
        return {"checked": scheme in LINE_CHECKSUMS,
                "refill": set(self.meta.get("repair", {}).get("dropped", ())),
                "run_uid": self.meta.get(RUN_UID) if LINE_CHECKSUMS.get(scheme) else None}

    def problems(self, lines: Lines, meta: dict[str, Any] | None = None) -> list[str]:
        """Every rule of the run but its lines' own, broken (one line each), as meta.json
        (`meta`: as read since the run was opened, else the run's) and these lines say:
        meta.json's own (gonio.run_rules), the digests, readings lost, sessions and counts."""
        meta = self.meta if meta is None else meta
        return (meta_problems(meta) + self.digest_damage
                + lost_and_session_problems(meta, lines, self.path))

    @functools.cached_property
    def digest_damage(self) -> list[str]:
        """digest_problems of the run, worked out once: the plan and config it compares were
        read when the run was opened, the register maps are read here (a live view asks for
        the run's problems at every poll)."""
        return digest_problems(self)

    def checked(self) -> tuple[Lines, list[str]]:
        """The lines as they are now, and the run's `problems` with them."""
        lines = self.lines()
        return lines, self.problems(lines)

    def refuse_damage(self) -> Lines:
        """The lines, once checked: DamagedRunError naming the first damage (a line, or a
        problem of `problems`) unless `force`."""
        lines, problems = self.checked()
        if (lines.damaged or problems) and not self.force:
            raise DamagedRunError(damage_message(self.path, lines, problems))
        return lines

    def rows(self) -> list[dict[str, Any]]:
        """The readings as dicts, by index (a torn last line is ignored), once refuse_damage
        lets them be read."""
        return self.refuse_damage().rows

    @functools.cached_property
    def read_past(self) -> list[str]:
        """The damage a read with `force` goes past ([] without force), one entry each."""
        return damage_list(*self.checked()) if self.force else []

    def resumable_lines(self) -> Lines:
        """The lines, once the run is found fit to resume: DamagedRunError for damage resume
        cannot mend (all but readings its record says were stored and its file lost, which
        resume measures again, and the digests, which the resume checks against its config);
        RunError for a completed run that lost none."""
        lines = self.lines()
        lost = lost_indices(self.meta, lines)
        problems = meta_problems(self.meta) + ([] if lost else
                                               session_problems(self.meta, lines))
        if lines.damaged or problems:
            raise DamagedRunError(damage_message(self.path, lines, problems, resume=True))
        if self.status == "completed" and not lost:
            raise RunError(f"{self.path}: run already completed; nothing to resume")
        return lines

    def readings(self) -> np.ndarray:
        """The readings as a numpy structured array with READING_DTYPE fields."""
        return readings_array(self.rows())

    def __len__(self) -> int:
        return len(self.rows())

    @property
    def status(self) -> str:
        """created | running | paused | suspended | completed | aborted | failed ("running" after
        a kill)."""
        return self.meta.get("status", "unknown")


def readings_array(rows: list[dict[str, Any]]) -> np.ndarray:
    """Stored readings (dicts, as `Run.rows` gives them) as a READING_DTYPE array."""
    out = np.zeros(len(rows), READING_DTYPE)
    for name in READING_DTYPE.names:
        if rows:
            out[name] = [_value(r.get(name), READING_DTYPE[name]) for r in rows]
    return out


def _value(v: Any, dtype: np.dtype) -> Any:
    """A line's value for a readings field: missing text is "", a missing number NaN."""
    if dtype.kind == "O":
        return "" if v is None else str(v)
    return np.nan if v is None else v


def open_run(path: str | Path, force: bool = False) -> Run:
    """Open a run directory for reading (`force`: see `Run`); RunError if it is not one, a
    DamagedRunError naming the way back for one that lost its meta.json."""
    path = Path(path)
    try:
        plan = json.loads((path / "plan.json").read_text())
        config = json.loads((path / "config.json").read_text())
        meta = json.loads((path / META).read_text())
    except FileNotFoundError as exc:
        if Path(exc.filename).name == META and (path / READINGS).exists():
            raise DamagedRunError(f"{path}: {META} is missing; `gonio check {path} --repair "
                                  f"OUT_DIR` rebuilds it from the readings, plan and config"
                                  ) from None
        raise RunError(f"{path}: not a run directory (missing {Path(exc.filename).name})") from None
    except (OSError, ValueError) as exc:
        raise DamagedRunError(f"{path}: damaged run directory ({exc})") from None
    if not (path / READINGS).exists():
        raise RunError(f"{path}: not a run directory (missing {READINGS})")
    return Run(path, plan, config, meta, force)


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


def _keep_reserve(run_dir: Path) -> None:
    """Write the run's reserve (random bytes: never sparse), as much of it as the disk takes."""
    with contextlib.suppress(OSError), open(run_dir / RESERVE, "wb") as fh:
        fh.write(os.urandom(RESERVE_BYTES))


def _move_into(tmp: Path, root: Path, base: str) -> Path:
    """Rename a complete run directory into root under the first free name base[-n]."""
    for n in range(1000):
        path = root / (base + (f"-{n}" if n else ""))
        if path.exists():
            continue
        try:
            tmp.rename(path)  # fails on an existing (never empty) run directory
        except OSError as exc:
            if exc.errno in (errno.EEXIST, errno.ENOTEMPTY):
                continue
            raise
        fsync_dir(root)
        return path
    raise RunError(f"{root}: cannot make a new run directory (1000 named {base}-n exist)")


class RunWriter:
    """Appends readings to a run directory, one fsynced line each, and keeps meta.json."""

    def __init__(self, path: Path, meta: dict[str, Any], next_index: int):
        self.path = path
        self.meta = meta
        self.next_index = next_index  # after the highest stored index
        self.missing: list[int] = []  # indices below it a repair dropped: measured first
        self._fh = _locked(path / READINGS)
        self._syncer: ThreadPoolExecutor | None = None  # started by the first append
        self._pending: Future | None = None  # the fsync of the last line written

    @classmethod
    def create(cls, root: Path, name: str, plan_file: Path | None, config_file: Path | None,
               plan: dict[str, Any], config: dict[str, Any], meta: dict[str, Any]) -> RunWriter:
        """Make a new run directory under root (name + UTC timestamp, unique), whole or not at
        all: StoreError (one line) if the disk refuses, and nothing is left behind."""
        stamp = datetime.now(UTC).strftime("%Y%m%dT%H%M%SZ")
        name = re.sub(r"[^A-Za-z0-9._-]", "_", name)[:60].lstrip(".") or "run"
        making, base = root / PARTIAL, f"{stamp}-{name}"
        tmp = making / f"{base}-{secrets.token_hex(4)}"
        try:
            making.mkdir(parents=True, exist_ok=True)
            tmp.mkdir()
        except OSError as exc:
            raise StoreError(f"{root}: cannot make a run directory there "
                             f"({exc.strerror or exc})") from None
        try:
            for src, dest in ((plan_file, "plan.toml"), (config_file, "instrument.toml")):
                if src is not None:
                    shutil.copyfile(src, tmp / dest)
            write_json_atomic(tmp / "plan.json", plan)
            write_json_atomic(tmp / "config.json", config)
            (tmp / READINGS).touch()
            _keep_reserve(tmp)
            meta = {**meta, "created_utc": utc_now(), "versions": versions(), "sessions": [],
                    "status": "created", "reason": "", "line_checksum": LINE_CHECKSUM,
                    RUN_UID: secrets.token_hex(8),
                    "digests": digests(plan, config)}
            write_json_atomic(tmp / META, meta)
            path = _move_into(tmp, root, base)
        except OSError as exc:
            raise StoreError(f"{root}: cannot make a run directory there "
                             f"({exc.strerror or exc})") from None
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
            with contextlib.suppress(OSError):
                making.rmdir()  # unless another run is being made there
        return cls(path, meta, 0)

    @classmethod
    def resume(cls, path: Path) -> RunWriter:
        """Reopen a run to continue it: refuse a damaged one (`Run.resumable_lines`), cut a
        torn last line, and go on with the indices a repair dropped and those its file lost,
        then after the last reading."""
        run = open_run(path)
        run.resumable_lines()  # refused before taking the lock
        writer = cls(path, run.meta, 0)  # takes the lock before touching the file
        try:
            lines = run.resumable_lines()
        except BaseException:
            writer._fh.close()
            raise
        if lines.torn_bytes:
            writer._fh.truncate(lines.keep_bytes)
            writer._fh.flush()
            os.fsync(writer._fh.fileno())
        if not (path / RESERVE).exists():  # freed by a full disk, or an older run
            _keep_reserve(path)
        top = max(lines.top, recorded_top(run.meta))
        writer.next_index = top + 1
        writer.missing = lines.missing() + list(range(lines.top + 1, top + 1))
        return writer

    @property
    def stored(self) -> int:
        """How many readings the run holds."""
        return self.next_index - len(self.missing)

    @property
    def expected(self) -> int:
        """The index the next `append` takes."""
        return self.missing[0] if self.missing else self.next_index

    def todo(self, planned: int) -> list[int]:
        """The indices still to measure, in the order `append` takes them."""
        return [*self.missing, *range(self.next_index, planned)]

    def start_session(self, **info: Any) -> None:
        """Record that a (new or resumed) session starts now."""
        refill = {"refill": list(self.missing)} if self.missing else {}
        self.meta["sessions"].append({"start_utc": utc_now(), "first_index": self.expected,
                                      **refill, **info})
        self.meta.setdefault("started_utc", self.meta["sessions"][0]["start_utc"])
        self.set_status("running", "")

    def set_status(self, status: str, reason: str) -> None:
        """Update status and reason in meta.json (atomically), once every reading is stored
        (StoreError if the disk refuses either)."""
        self.wait_stored()
        self.meta["status"], self.meta["reason"], self.meta["stored"] = status, reason, self.stored
        if status != "running":
            self.meta["stopped_utc"] = utc_now()
            if self.meta["sessions"]:
                self.meta["sessions"][-1].update(stop_utc=self.meta["stopped_utc"],
                                                 status=status, last_index=self.next_index - 1)
        try:
            write_json_atomic(self.path / META, self.meta)
        except OSError as exc:
            if exc.errno != errno.ENOSPC or not (self.path / RESERVE).exists():
                raise StoreError(f"cannot write {self.path / META}: "
                                 f"{exc.strerror or exc}") from None
            (self.path / RESERVE).unlink()  # the disk is full: use the room kept for this
            self.set_status(status, reason)

    def append(self, row: dict[str, Any]) -> None:
        """Write one reading (its index must be the next one) and start its fsync, once the
        previous reading's fsync has returned (see the module docstring)."""
        if row["index"] != self.expected:
            raise RunError(f"{self.path}: reading {row['index']} out of order "
                           f"(expected {self.expected})")
        line = encode_line(row, run_uid=self.meta.get(RUN_UID))
        self.wait_stored()
        try:  # in the kernel's hands once written: a killed process no longer loses it
            written = 0
            while written < len(line):
                written += self._fh.write(line[written:])
        except OSError as exc:  # what the disk took of the line is a torn tail
            raise StoreError(f"cannot store reading {row['index']} in "
                             f"{self.path / READINGS}: {exc.strerror or exc}") from None
        if self.missing:
            self.missing.pop(0)
        else:
            self.next_index += 1
        if self._syncer is None:
            self._syncer = ThreadPoolExecutor(1, thread_name_prefix="run-fsync")
        self._pending = self._syncer.submit(os.fsync, self._fh.fileno())

    def wait_stored(self) -> None:
        """Return once every appended reading is fsynced (StoreError, once, if the disk
        refused). Interrupted (Ctrl-C), the fsync stays pending: the next call waits again."""
        pending = self._pending
        if pending is None:
            return
        try:
            pending.result()
        except OSError as exc:
            raise StoreError(f"cannot store {self.path / READINGS}: "
                             f"{exc.strerror or exc}") from None
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
