"""Rebuilding a lost meta.json from what the run directory still holds: its readings, plan.json
and config.json (`gonio check RUN --repair OUT_DIR` then writes the repaired copy with it).

The run's identity comes from its lines: each carries the run's uid (`run`) under its
checksum, so the uid most valid lines carry is the run's, and lines of another run stay damage.
The digests are taken from plan.json and config.json as found (nothing is left to compare
them with), the planned count from the plan scheduled on the config, the time origin from the
readings file's last change less its latest `t_s`; sessions, seeds and device identities are
lost. The status is `completed` when every planned reading is there, else `failed`, so that
`gonio scan --resume` measures the rest.
"""

from __future__ import annotations

import json
import os
import zlib
from collections import Counter
from pathlib import Path
from typing import Any

from gonio.completeness import planned_readings
from gonio.run_rules import CRC, LINE_CHECKSUM, RUN_UID
from gonio.store import META, READINGS, RUN_FIELD, Run, canonical_json, digests, utc_now


def line_uid(line: bytes) -> str | None:
    """The run uid a line carries under a checksum that holds (None: none, or not valid)."""
    try:
        row = json.loads(line)
    except ValueError:
        return None
    if not isinstance(row, dict):
        return None
    crc, uid = row.pop(CRC, None), row.get(RUN_FIELD)
    if crc != zlib.crc32(canonical_json(row)) or not isinstance(uid, str):
        return None
    return uid


def lost_meta(path: Path) -> bool:
    """Whether `path` is a run directory that lost its meta.json (its readings are there)."""
    return not (path / META).exists() and (path / READINGS).exists()


def recovered_run(path: Path) -> Run:
    """The run at `path` with a meta.json rebuilt in memory (see the module docstring; its
    `recovered` record says so); RunError/DamagedRunError as `open_run` for a directory
    without plan.json, config.json or readings."""
    plan = json.loads((path / "plan.json").read_text())
    config = json.loads((path / "config.json").read_text())
    data = (path / READINGS).read_bytes()
    uids = Counter(u for u in map(line_uid, data.split(b"\n")) if u is not None)
    identity = {"line_checksum": LINE_CHECKSUM, RUN_UID: uids.most_common(1)[0][0]} if uids \
        else {"line_checksum": CRC}
    meta: dict[str, Any] = {
        "plan_name": plan.get("name"), "instrument_name": config.get("name"), "sim": False,
        "sessions": [], "status": "failed", "reason": "", **identity,
        "digests": digests(plan, config),
        "recovered": {"utc": utc_now(), "from": [READINGS, "plan.json", "config.json"],
                      "run_uids_seen": dict(uids),
                      "note": f"{META} was lost: the digests are plan.json's and "
                              f"config.json's as found, t0_epoch is approximate; sessions, "
                              f"seeds and device identities are unknown"}}
    run = Run(path, plan, config, meta)
    meta["planned"] = planned_readings(run)
    lines = run.lines()
    meta["stored"] = len(lines.rows)
    latest_t_s = max((r["t_s"] for r in lines.rows if isinstance(r.get("t_s"), float | int)),
                     default=0.0)
    meta["t0_epoch"] = os.stat(path / READINGS).st_mtime - latest_t_s
    if meta["planned"] is not None and len(lines.rows) >= meta["planned"] \
            and not lines.missing():
        meta["status"] = "completed"
    meta["reason"] = (f"{META} rebuilt by gonio check --repair from {len(lines.rows)} readings, "
                      f"plan.json and config.json")
    return run
