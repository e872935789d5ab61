"""The plan queue of an output folder: OUT/queue.toml lists queued plans in order (each with
a stable id, its plan's copy, instrument, --sim, state and run directory); `run_entry` starts
or resumes one through the scan runner and records where it goes and how it ends.

queue.toml is only ever replaced whole (temporary file, fsync, rename) while holding
OUT/queue/state.lock, so `gonio queue add` may append while a queue runs; OUT/queue/run.lock
is held by the one `gonio queue run` working the folder. The plans are copied in at add time
(OUT/queue/NN/NAME.toml): a queued run measures what was validated, whatever becomes of the
original file. The verb itself is gonio_cli/commands/queue.py.

queue.toml may be edited by hand, even while its queue runs: every change the runner records
re-reads the file under the state lock and finds its entry by id, never by position (a file
written without ids gets them at its first change, `queue add` or `queue run`). A run
directory counts for an entry only while the plan digest its meta.json recorded is that of
the entry's plan copy and no other entry names it, so no edit marks an unmeasured plan
completed; an entry deleted while it ran has its outcome in its run directory only.
"""

from __future__ import annotations

import dataclasses
import fcntl
import json
import os
import secrets
import shutil
import tomllib
from collections.abc import Callable, Collection, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from drivers.base import DriverError
from drivers.user_file import SETTINGS_FILE_CAP, read_user_text
from gonio.config import load_config
from gonio.engine import Outcome, PauseControl
from gonio.errors import GonioError, QueueError, RunError, Terminated, os_error_text
from gonio.fields import Fields
from gonio.plan import load_plan
from gonio.runner import ScanResult, instrument_path, new_scan, resume_scan, schedule_for
from gonio.store import digest, open_run, utc_now, write_text_atomic

QUEUE_FILE = "queue.toml"
QUEUE_DIR = "queue"  # the plan copies and the two lock files
STATES = ("pending", "running", "completed", "failed", "aborted")
HEADER = """\
# The plan queue of this folder: `gonio queue add` appends entries, `gonio queue run` runs them
# in order and records each one's run directory (a folder here) and state
# (pending | running | completed | failed | aborted), finding each entry by its id.
# Rewritten whole at every change.
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
    id: str = ""  # stable, unique in the file ("" until the file's first change gives it one)

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
    entries = survey(out)
    for entry in entries:
        if isinstance(entry, QueueError):
            raise entry
    return entries


def survey(out: Path) -> list[Entry | QueueError]:
    """Each entry of the folder's queue file, or the QueueError naming what is wrong with it;
    QueueError itself when the file as a whole cannot be read."""
    path = queue_path(out)
    if not path.exists() and not path.is_symlink():
        return []
    text = read_user_text(path, "queue file", SETTINGS_FILE_CAP, QueueError)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise QueueError(f"{path}: not a valid queue file ({exc})") from None
    top = Fields(data, str(path), QueueError)
    top.has("entry")
    top.done()
    tables = data.get("entry", [])
    if not isinstance(tables, list):
        raise top.fail("entry", "must be an array of tables ([[entry]])")
    out_entries: list[Entry | QueueError] = []
    seen: dict[str, int] = {}
    for n, table in enumerate(tables, 1):
        try:
            entry = _entry(Fields(table, str(path), QueueError, f"entry[{n}]"))
        except QueueError as exc:
            out_entries.append(exc)
            continue
        if entry.id in seen:
            out_entries.append(QueueError(f"{path}: [entry[{n}]] id: {entry.id!r} is also "
                                          f"entry[{seen[entry.id]}]'s; ids are unique"))
            continue
        if entry.id:
            seen[entry.id] = n
        out_entries.append(entry)
    return out_entries


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
                  run=f.string("run", default=""), reason=f.string("reason", default=""),
                  id=f.string("id", default=""))
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
    """queue.toml's text for these entries, each one's id first."""
    return HEADER + "".join(
        f"\n[[entry]]\nid = {_toml(e.id)}\n" + "".join(
            f"{k} = {_toml(v)}\n" for k, v in dataclasses.asdict(e).items() if k != "id")
        for e in entries)


def _lock_file(out: Path, name: str) -> Any:
    """A lock file of the queue, open for flock (a lock is released when the process ends,
    even by SIGKILL)."""
    path = Path(out) / QUEUE_DIR / name
    path.parent.mkdir(parents=True, exist_ok=True)
    return open(path, "a+")


@contextmanager
def _editing(out: Path) -> Iterator[list[Entry]]:
    """The entries as the file says now, each with an id (one given to any without), to
    change in place; written back whole on success, all under the state lock (a failure
    inside changes nothing)."""
    with _lock_file(out, "state.lock") as fh:
        fcntl.flock(fh.fileno(), fcntl.LOCK_EX)
        entries = load(out)
        for n, entry in enumerate(entries):
            if not entry.id:
                entries[n] = replace(entry, id=new_id(entries))
        yield entries
        write_text_atomic(queue_path(out), render(entries))


def new_id(entries: Sequence[Entry]) -> str:
    """An entry id none of `entries` has."""
    taken = {e.id for e in entries}
    while (made := secrets.token_hex(4)) in taken:
        pass
    return made


def identify(out: Path) -> list[Entry]:
    """The folder's entries, after giving an id to each that had none (written back)."""
    with _editing(out) as entries:
        return list(entries)


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
                folder = _free_folder(out, entries)
                shutil.rmtree(folder, ignore_errors=True)  # left by an add that was killed
                made.append(folder)
                entries.append(replace(_copied(source, folder, out, instrument, sim),
                                       id=new_id(entries)))
            added = list(enumerate(entries[first - 1:], first))
    except BaseException:
        for folder in made:
            shutil.rmtree(folder, ignore_errors=True)
        raise
    return added


def _free_folder(out: Path, entries: Sequence[Entry]) -> Path:
    """The plan-copy folder for a new entry: OUT/queue/NN, NN from the entry's position up to
    the first no entry's plan copy is in (a hand edit may have deleted an earlier entry)."""
    taken = {Path(e.plan).parent for e in entries}
    n = len(entries) + 1
    while Path(QUEUE_DIR, f"{n:02d}") in taken:
        n += 1
    return out / QUEUE_DIR / f"{n:02d}"


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
    write_text_atomic(copy, read_user_text(source, "plan", SETTINGS_FILE_CAP, QueueError))
    return Entry(plan=str(copy.relative_to(out)), source=str(source.resolve()),
                 instrument=str(cfg_path),
                 sim=sim if isinstance(sim, bool) else tuple(sim), planned=len(sched),
                 added_utc=utc_now())


def next_position(entries: Sequence[Entry], passed: Collection[int] = ()) -> int | None:
    """The position (from 1) of the first entry not completed and not passed over, if any."""
    return next((n for n, e in enumerate(entries, 1)
                 if e.state != "completed" and n not in passed), None)


def readings_of(out: Path, entry: Entry) -> tuple[int | None, int, str]:
    """(stored, planned, problem) for an entry: from its run directory once it has one
    (stored None and the problem named if that cannot be read), else (0, planned at add
    time, "")."""
    if not entry.run:
        return 0, entry.planned, ""
    try:
        run = open_run(Path(out) / entry.run)
        return len(run.lines().rows), int(run.meta.get("planned", entry.planned)), ""
    except (RunError, OSError) as exc:
        return None, entry.planned, str(exc) if isinstance(exc, RunError) else os_error_text(exc)
    except Exception as exc:  # noqa: BLE001 - whatever a hand-made folder holds is named
        return None, entry.planned, f"{Path(out) / entry.run}: unreadable run directory ({exc})"


def run_problem(out: Path, entry: Entry, run: str, entries: Sequence[Entry]) -> str | None:
    """Why run directory `run` cannot be the entry's (another entry names it, it or the
    entry's plan copy cannot be read, or its recorded plan digest is not the copy's), or
    None when it can."""
    others = [e for e in entries
              if e.run == run and (e.id, e.plan) != (entry.id, entry.plan)]
    if others:
        return f"run {run} is also the run of entry {others[0].id or others[0].plan}"
    try:
        recorded = open_run(Path(out) / run).meta.get("digests", {})
        recorded = recorded.get("plan.json") if isinstance(recorded, dict) else None
        planned = digest(load_plan(Path(out) / entry.plan).raw)
    except (GonioError, OSError, AttributeError) as exc:
        text = os_error_text(exc) if isinstance(exc, OSError) else str(exc)
        return f"run {run} cannot be checked against the entry's plan ({text})"
    if recorded != planned:
        return (f"run {run} was not measured from the entry's plan {entry.plan} "
                f"(the plan digest its meta.json records differs)")
    return None


def _record(out: Path, entry_id: str, **changes: Any) -> Entry | None:
    """Apply changes to the entry with this id as queue.toml says it now (under the state
    lock); None, changing nothing, when no entry has the id any more. A change to
    `completed` is recorded only for a run that run_problem accepts, else as failed."""
    with _editing(out) as entries:
        position = next((n for n, e in enumerate(entries) if e.id == entry_id), None)
        if position is None:
            return None
        entry = replace(entries[position], **changes)
        problem = run_problem(out, entry, entry.run, entries) \
            if entry.state == "completed" else None
        if problem is not None:
            entry = replace(entry, state="failed", reason=problem)
        entries[position] = entry
        return entry


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


def run_entry(out: Path, entry_id: str, control: PauseControl, progress: bool | None = None,
              warn: Callable[[str], None] | None = None) -> ScanResult:
    """Run the entry with this id: resume its run when it has a run directory (a crash, a
    failure, an abort) that run_problem accepts, else start one, whose directory goes into
    queue.toml as soon as it exists; record the state it ends in. An exception or signal that
    ends it before the engine's outcome is recorded (failed / aborted) and propagates, as
    does a QueueError for a run not accepted or for an id no entry has (then nothing is
    measured: its start could not be recorded); an entry deleted while it runs is told to
    `warn`."""
    out = Path(out)
    entries = load(out)
    entry = next((e for e in entries if e.id == entry_id), None) if entry_id else None
    if entry is None:
        raise QueueError(f"{queue_path(out)}: no entry has id {entry_id!r} any more")
    run = entry.run

    def created(path: Path) -> None:
        nonlocal run
        run = path.name
        _record(out, entry_id, run=run)

    if _record(out, entry_id, state="running", reason="") is None:
        raise QueueError(f"{queue_path(out)}: no entry has id {entry_id!r} any more")
    try:
        if run:
            problem = run_problem(out, entry, run, entries)
            if problem is not None:
                raise QueueError(f"{queue_path(out)}: entry {entry_id}: {problem}; "
                                 f"clear its `run` to measure it afresh")
            result = _resume(out / run, control, progress)
        else:
            result = new_scan(out / entry.plan, entry.instrument, entry.sim_arg, out,
                              progress=progress, control=control, warn=warn, created=created)
    except BaseException as exc:
        aborted = isinstance(exc, KeyboardInterrupt | Terminated)
        _record(out, entry_id, state="aborted" if aborted else "failed", run=run,
                reason=reason_of(exc))
        raise
    status = result.outcome.status
    recorded = _record(out, entry_id, state=status, reason=result.outcome.reason, run=run)
    if recorded is None:
        if warn is not None:
            warn(f"entry {entry_id} left {queue_path(out)} while it ran: its outcome "
                 f"({status}) is recorded in {result.path} only")
    elif recorded.state != status:
        raise QueueError(f"{queue_path(out)}: entry {entry_id}: {recorded.reason}")
    return result
