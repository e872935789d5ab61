"""The plan queue of an output folder: OUT/queue.toml lists queued plans in order (each with
its plan's copy, instrument, --sim, state and run directory); `run_entry` starts or resumes
one through the scan runner and records where it goes and how it ends.

queue.toml is only ever replaced whole (temporary file, fsync, rename) while holding
OUT/queue/state.lock, so `gonio queue add` may append while a queue runs; OUT/queue/run.lock
is held by the one `gonio queue run` working the folder. The plans are copied in at add time
(OUT/queue/NN/NAME.toml): a queued run measures what was validated, whatever becomes of the
original file. The verb itself is gonio_cli/commands/queue.py.
"""

from __future__ import annotations

import dataclasses
import fcntl
import json
import os
import shutil
import tomllib
from collections.abc import Callable, Collection, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from drivers.base import DriverError
from gonio.config import load_config
from gonio.engine import Outcome, PauseControl
from gonio.errors import GonioError, QueueError, RunError, Terminated, os_error_text
from gonio.fields import Fields
from gonio.plan import load_plan
from gonio.runner import ScanResult, instrument_path, new_scan, resume_scan, schedule_for
from gonio.store import open_run, utc_now, write_text_atomic

QUEUE_FILE = "queue.toml"
QUEUE_DIR = "queue"  # the plan copies and the two lock files
STATES = ("pending", "running", "completed", "failed", "aborted")
HEADER = """\
# The plan queue of this folder: `gonio queue add` appends entries, `gonio queue run` runs them
# in order and records each one's run directory (a folder here) and state
# (pending | running | completed | failed | aborted). Rewritten whole at every change.
"""


@dataclass(frozen=True)
class Entry:
    """One queued plan, as queue.toml records it."""

    plan: str  # its copy, relative to the queue's folder: queue/NN/NAME.toml
    source: str  # the file it was copied from (absolute)
    instrument: str  # the instrument config it runs on (absolute)
    sim: bool | tuple[str, ...]  # --sim: False, True (every device) or device / role names
    planned: int  # readings in its schedule when added
    added_utc: str
    state: str = "pending"
    run: str = ""  # its run directory's name in the folder, once that exists
    reason: str = ""  # why it failed or was aborted

    @property
    def sim_arg(self) -> list[str] | bool:
        """sim as the scan runner takes it."""
        return self.sim if isinstance(self.sim, bool) else list(self.sim)


def queue_path(out: Path) -> Path:
    """The queue file of an output folder."""
    return Path(out) / QUEUE_FILE


def load(out: Path) -> list[Entry]:
    """The folder's entries in order ([] when it has no queue file); QueueError naming the
    entry and the field for anything queue.toml should not say."""
    path = queue_path(out)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return []
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise QueueError(f"{path}: not a valid queue file ({exc})") from None
    top = Fields(data, str(path), QueueError)
    top.has("entry")
    top.done()
    tables = data.get("entry", [])
    if not isinstance(tables, list):
        raise top.fail("entry", "must be an array of tables ([[entry]])")
    return [_entry(Fields(t, str(path), QueueError, f"entry[{n}]"))
            for n, t in enumerate(tables, 1)]


def _entry(f: Fields) -> Entry:
    if not f.has("sim"):
        raise f.error(f"{f.where}: missing required key 'sim'")
    sim = f.table["sim"]
    valid_sim = isinstance(sim, bool) or (
        isinstance(sim, list) and bool(sim) and all(isinstance(s, str) and s for s in sim))
    if not valid_sim:
        raise f.fail("sim", f"must be true, false or a list of device names, got {sim!r}")
    entry = Entry(plan=f.string("plan"), source=f.string("source"),
                  instrument=f.string("instrument"),
                  sim=sim if isinstance(sim, bool) else tuple(sim),
                  planned=f.number("planned", low=0, integer=True),
                  added_utc=f.string("added_utc"), state=f.string("state", choices=STATES),
                  run=f.string("run", default=""), reason=f.string("reason", default=""))
    f.done()
    if entry.run and (Path(entry.run).name != entry.run or entry.run in (".", "..")):
        raise f.fail("run", f"must be the name of a run directory in the folder, "
                            f"got {entry.run!r}")
    if entry.state == "completed" and not entry.run:
        raise f.fail("run", "missing: a completed entry names its run directory")
    return entry


def _toml(value: Any) -> str:
    """A queue field as TOML: bool, int, string or a list of strings."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, str):  # JSON's escapes are TOML's; DEL must be escaped in TOML
        return json.dumps(value, ensure_ascii=False).replace("\x7f", "\\u007f")
    return "[" + ", ".join(_toml(v) for v in value) + "]"


def render(entries: Sequence[Entry]) -> str:
    """queue.toml's text for these entries."""
    return HEADER + "".join(
        "\n[[entry]]\n" + "".join(f"{k} = {_toml(v)}\n"
                                  for k, v in dataclasses.asdict(e).items())
        for e in entries)


def _lock_file(out: Path, name: str) -> Any:
    """A lock file of the queue, open for flock (a lock is released when the process ends,
    even by SIGKILL)."""
    path = Path(out) / QUEUE_DIR / name
    path.parent.mkdir(parents=True, exist_ok=True)
    return open(path, "a+")


@contextmanager
def _editing(out: Path) -> Iterator[list[Entry]]:
    """The entries, to change in place; written back whole on success, all under the state
    lock (a failure inside changes nothing)."""
    with _lock_file(out, "state.lock") as fh:
        fcntl.flock(fh.fileno(), fcntl.LOCK_EX)
        entries = load(out)
        yield entries
        write_text_atomic(queue_path(out), render(entries))


def existing(out: Path) -> list[Entry]:
    """The folder's entries; QueueError if it has none (no queue.toml, or an empty one)."""
    entries = load(out)
    if not entries:
        raise QueueError(f"{out}: no queue here (no entry in {queue_path(out)}): add plans "
                         f"with `gonio queue add PLAN --out {out}`")
    return entries


@contextmanager
def run_lock(out: Path) -> Iterator[None]:
    """Hold the folder's run lock while its queue runs; QueueError (naming the holder's pid)
    if another process holds it, or if the folder has no queue."""
    existing(out)
    with _lock_file(out, "run.lock") as fh:
        try:
            fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            fh.seek(0)
            holder = fh.read().strip() or "unknown"
            raise QueueError(f"{out}: its queue is being run by another `gonio queue run` "
                             f"(pid {holder}); one at a time") from None
        fh.truncate(0)
        fh.write(f"{os.getpid()}\n")
        fh.flush()
        yield


def add(out: Path, plans: Sequence[str | Path], instrument: str | Path | None,
        sim: list[str] | bool) -> list[tuple[int, Entry]]:
    """Validate each plan against its instrument config as `gonio plan` does (and --sim's
    names), copy it into the queue and append its entry: one bad plan raises its PlanError /
    ConfigError and adds nothing. Returns the (position, entry) of each added."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    made: list[Path] = []
    try:
        with _editing(out) as entries:
            first = len(entries) + 1
            for source in map(Path, plans):
                folder = out / QUEUE_DIR / f"{len(entries) + 1:02d}"
                shutil.rmtree(folder, ignore_errors=True)  # left by an add that was killed
                made.append(folder)
                entries.append(_copied(source, folder, out, instrument, sim))
            added = list(enumerate(entries[first - 1:], first))
    except BaseException:
        for folder in made:
            shutil.rmtree(folder, ignore_errors=True)
        raise
    return added


def _copied(source: Path, folder: Path, out: Path, instrument: str | Path | None,
            sim: list[str] | bool) -> Entry:
    """The plan, once validated (errors name the original), copied into folder, and its entry.
    The copy keeps the file name (a plan's name defaults to it); its own `instrument`, relative
    to the original's folder, is resolved here and recorded in the entry."""
    plan = load_plan(source)
    cfg_path = instrument_path(plan, instrument).resolve()
    sched = schedule_for(plan, load_config(cfg_path), sim)
    folder.mkdir(parents=True)
    copy = folder / source.name
    write_text_atomic(copy, source.read_text(encoding="utf-8"))
    return Entry(plan=str(copy.relative_to(out)), source=str(source.resolve()),
                 instrument=str(cfg_path),
                 sim=sim if isinstance(sim, bool) else tuple(sim), planned=len(sched),
                 added_utc=utc_now())


def next_position(entries: Sequence[Entry], passed: Collection[int] = ()) -> int | None:
    """The position (from 1) of the first entry not completed and not passed over, if any."""
    return next((n for n, e in enumerate(entries, 1)
                 if e.state != "completed" and n not in passed), None)


def readings_of(out: Path, entry: Entry) -> tuple[int | None, int]:
    """(stored, planned) readings of an entry: from its run directory once it has one
    (stored None if that cannot be read), else (0, planned at add time)."""
    if not entry.run:
        return 0, entry.planned
    try:
        run = open_run(Path(out) / entry.run)
        return len(run.lines().rows), int(run.meta.get("planned", entry.planned))
    except (RunError, OSError):
        return None, entry.planned


def _set(out: Path, position: int, **changes: Any) -> None:
    with _editing(out) as entries:
        entries[position - 1] = replace(entries[position - 1], **changes)


def reason_of(exc: BaseException) -> str:
    """An exception that ended an entry, as its recorded reason."""
    if isinstance(exc, Terminated):
        return f"terminated by {exc}"
    if isinstance(exc, KeyboardInterrupt):
        return "interrupted"
    if isinstance(exc, OSError):
        return os_error_text(exc)
    if isinstance(exc, GonioError | DriverError):
        return str(exc)
    return f"{type(exc).__name__}: {exc}"


def _resume(path: Path, control: PauseControl, progress: bool | None) -> ScanResult:
    """Resume an entry's run, as the run was started; a run that completed before the queue
    could record it (a kill in between) is simply completed."""
    run = open_run(path)
    if run.status == "completed":
        return ScanResult(run.path, Outcome("completed", "", len(run.lines().rows)))
    return resume_scan(path, control=control, progress=progress)


def run_entry(out: Path, position: int, control: PauseControl, progress: bool | None = None,
              warn: Callable[[str], None] | None = None) -> ScanResult:
    """Run the entry at `position`: resume its run when it has a run directory (a crash, a
    failure, an abort), else start one, whose directory goes into queue.toml as soon as it
    exists; record the state it ends in. An exception or signal that ends it before the
    engine's outcome is recorded (failed / aborted) and propagates."""
    out = Path(out)
    entry = load(out)[position - 1]
    run = entry.run

    def created(path: Path) -> None:
        nonlocal run
        run = path.name
        _set(out, position, run=run)

    _set(out, position, state="running", reason="")
    try:
        if run:
            result = _resume(out / run, control, progress)
        else:
            result = new_scan(out / entry.plan, entry.instrument, entry.sim_arg, out,
                              progress=progress, control=control, warn=warn, created=created)
    except BaseException as exc:
        aborted = isinstance(exc, KeyboardInterrupt | Terminated)
        _set(out, position, state="aborted" if aborted else "failed", run=run,
             reason=reason_of(exc))
        raise
    _set(out, position, state=result.outcome.status, reason=result.outcome.reason)
    return result
