"""Export a run as Bluesky's event-model documents, one `["name", {document}]` pair per line
as suitcase-jsonl writes them: a start (the run's record under `gonio`), one `primary`
descriptor, one event per stored reading in index order and, once the run has ended, a stop.

Every document is built and validated by event-model's composers (its JSON schemas). The
events' data keys are the readings' fields (gonio.store.READING_DTYPE); a NaN (an invalid
reading's power, a dark reading's plan angles) is written as NaN, as the RunEngine's own
documents carry it (Python's json), so that a reader that infers a column's type from the
values (Tiled's TiledWriter) keeps a numeric field numeric. An
event's `time` is wall time: t0_epoch + t_s, or for a run on the emulated bench's virtual clock
(whose t_s is run time) one placed from its session's wall stamps, t_s staying in the data. uids are
derived from the run's start, so exporting a run twice gives the same file, and a catalog that
holds the run already refuses it a second time (Tiled: HTTP 409 Conflict).
"""

from __future__ import annotations

import json
import uuid
from datetime import datetime
from pathlib import Path
from typing import Any

from calibration.exports.cf import reading_unit
from gonio.errors import GonioError
from gonio.record import on_virtual_clock, run_record
from gonio.store import READING_DTYPE, READINGS, Run

EXIT_STATUS = {"completed": "success", "aborted": "abort", "failed": "fail"}
DTYPES = {"i": "integer", "f": "number", "b": "boolean", "O": "string"}  # numpy kind -> JSON


def data_keys() -> dict[str, dict[str, Any]]:
    """The primary descriptor's data keys: one per reading field, with its unit."""
    keys = {}
    for name in READING_DTYPE.names:
        keys[name] = {"dtype": DTYPES[READING_DTYPE[name].kind], "shape": [],
                      "source": f"gonio:{READINGS}:{name}"}
        if reading_unit(name):
            keys[name]["units"] = reading_unit(name)
    return keys


def _plain(value: Any) -> Any:
    """A readings value as Python has it: a numpy scalar's Python value (NaN stays NaN)."""
    return value.item() if hasattr(value, "item") else value


def _wall(stamp: str) -> float:
    """An ISO 8601 stamp of meta.json (gonio.store.utc_now) as epoch seconds."""
    return datetime.fromisoformat(stamp).timestamp()


def _session_wall_time(session: dict[str, Any], t_s: float) -> float:
    """When, in wall time, a reading at run time `t_s` of a virtual-clock session was taken:
    its place in the session's virtual span laid over the session's wall span (start_utc to
    stop_utc); the session's start for one killed outright (it recorded no end)."""
    start = _wall(session["start_utc"])
    if "stop_utc" not in session or "clock_end_s" not in session:
        return start
    begin, end = float(session.get("clock_start_s", 0.0)), float(session["clock_end_s"])
    share = min(max((t_s - begin) / (end - begin), 0.0), 1.0) if end > begin else 0.0
    return start + share * (_wall(session["stop_utc"]) - start)


def event_time(meta: dict[str, Any], t_s: float) -> float:
    """A reading's event time, epoch seconds: `t0_epoch` + `t_s` for a run on the wall clock;
    for one on the emulated bench's virtual clock (whose `t_s` is run time, never wall time),
    from the wall stamps of the session it belongs to (the last to start at or before t_s)."""
    if not on_virtual_clock(meta):
        return float(meta["t0_epoch"]) + t_s
    sessions = meta["sessions"]
    own = [s for s in sessions if float(s.get("clock_start_s", 0.0)) <= t_s] or sessions[:1]
    return _session_wall_time(own[-1], t_s)


def documents(run: Run) -> list[tuple[str, dict[str, Any]]]:
    """The run's documents in order: start, descriptor, events, and stop once it has ended."""
    try:
        import event_model
    except ImportError:
        raise GonioError("the bluesky export needs event-model "
                         "(pip install 'gonio[bluesky]')") from None
    meta = run.meta
    t0 = float(meta["t0_epoch"])
    start_uid = str(uuid.uuid5(uuid.NAMESPACE_URL, f"gonio-run:{run.path.name}:{t0!r}"))
    bundle = event_model.compose_run(uid=start_uid, time=t0, metadata={
        "plan_name": meta.get("plan_name"), "num_points": meta.get("planned"),
        "instrument_name": meta.get("instrument_name"), "gonio": run_record(run)})
    descriptor = bundle.compose_descriptor(
        name="primary", data_keys=data_keys(), time=t0,
        uid=str(uuid.uuid5(uuid.UUID(start_uid), "primary")))
    docs: list[tuple[str, dict[str, Any]]] = [("start", bundle.start_doc),
                                              ("descriptor", descriptor.descriptor_doc)]
    readings = run.readings()
    for seq, row in enumerate(readings, start=1):
        when = event_time(meta, float(row["t_s"]))
        data = {name: _plain(row[name]) for name in READING_DTYPE.names}
        docs.append(("event", descriptor.compose_event(
            data=data, timestamps=dict.fromkeys(data, when), seq_num=seq, time=when,
            uid=str(uuid.uuid5(uuid.UUID(start_uid), f"event-{int(row['index'])}")))))
    status = meta.get("status")
    if status in EXIT_STATUS:
        stopped = meta.get("stopped_utc")
        end = _wall(stopped) if stopped else \
            event_time(meta, float(readings["t_s"].max(initial=0.0)))
        docs.append(("stop", bundle.compose_stop(
            exit_status=EXIT_STATUS[status], reason=meta.get("reason") or "", time=end,
            uid=str(uuid.uuid5(uuid.UUID(start_uid), "stop")))))
    return docs


def write_jsonl(run: Run, out: Path) -> Path:
    """The run's documents as JSON lines, one `["name", {document}]` pair a line; NaN as
    Python's json writes it (`NaN`), which json.loads, suitcase-jsonl and Tiled read back."""
    with open(out, "w") as fh:
        for name, doc in documents(run):
            fh.write(json.dumps([name, doc], allow_nan=True) + "\n")
    return out
