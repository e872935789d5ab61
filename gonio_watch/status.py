"""The live view's status of a run, from what the run directory holds (meta.json, the readings
so far) and, when the scan answers on its control channel, its live state: status, readings
stored of planned, elapsed time and ETA, the stages' last positions, suspensions; and, once
the run has ended, whether it is incomplete (gonio.completeness)."""

from __future__ import annotations

import statistics
from dataclasses import dataclass
from datetime import datetime
from typing import Any

from gonio.completeness import completeness_of
from gonio.plan import MOTION_ROLES
from gonio.store import Run

ENDED = ("completed", "aborted", "failed")  # meta.json's statuses of a run that has ended
RATE_READINGS = 20  # the ETA takes the median time per reading over the last ones


@dataclass(frozen=True)
class Live:
    """What the control channel said: `reply` the scan's answer to `status` (None: not
    asked, no token), `reachable` whether a scan listens, `why` a one-line explanation when
    the pause, resume and abort buttons cannot work."""

    reachable: bool
    reply: dict[str, Any] | None = None
    why: str = ""

    @property
    def state(self) -> str | None:
        """The engine's state, when the scan told it."""
        return self.reply.get("state") if self.reply and self.reply.get("ok") else None


def combined_status(meta_status: str, live: Live) -> str:
    """The scan's own state when it answers; else meta.json's status for an ended run or one
    whose scan process listens; else "not running" (the process ended without recording an
    end: killed, or the machine went down)."""
    if live.state:
        return live.state
    if meta_status in ENDED or live.reachable:
        return meta_status
    return "not running"


def _epoch(utc: str) -> float:
    return datetime.fromisoformat(utc).timestamp()


def real_per_t_s(meta: dict[str, Any]) -> float | None:
    """Real seconds per second of the run's `t_s`: 1 on the wall clock; on an all-emulated
    bench's virtual clock (a session's `clock` "virtual") 1 / time_scale, None when instant
    (its t_s says nothing of real time)."""
    sessions = meta.get("sessions", [])
    if not sessions or sessions[-1].get("clock") != "virtual":
        return 1.0
    scale = meta.get("time_scale", 1.0)
    return None if scale == "inf" else 1.0 / float(scale)


def elapsed_s(meta: dict[str, Any], running: bool, now: float, last_t_s: float | None) -> float:
    """Seconds the run's sessions have lasted: each from its start to its recorded stop; the
    last one, unstopped, until now while it runs, else until its last reading (on the wall
    clock; on a virtual one such a session's end is unknown)."""
    total, sessions = 0.0, meta.get("sessions", [])
    for k, session in enumerate(sessions):
        start = _epoch(session["start_utc"])
        if session.get("stop_utc"):
            stop = _epoch(session["stop_utc"])
        elif running and k == len(sessions) - 1:
            stop = now
        elif last_t_s is not None and session.get("clock") != "virtual":
            stop = float(meta.get("t0_epoch", start)) + last_t_s
        else:
            stop = start
        total += max(stop - start, 0.0)
    return total


def session_start_t_s(meta: dict[str, Any]) -> float:
    """The t_s the last session started at: on the wall clock its start less t0_epoch, on a
    virtual one its recorded `clock_start_s`."""
    sessions = meta.get("sessions", [])
    if not sessions:
        return 0.0
    if sessions[-1].get("clock") == "virtual":
        return float(sessions[-1].get("clock_start_s", 0.0))
    return _epoch(sessions[-1]["start_utc"]) - float(meta.get("t0_epoch", 0.0))


def eta_s(meta: dict[str, Any], rows: list[dict[str, Any]], planned: int
          ) -> tuple[float | None, str]:
    """(seconds still to go, how it was estimated): the median time per reading over this
    session's last readings times the readings left, or the plan's estimate pro rata before
    two readings of this session are in (or on an instant virtual clock); (None, why) when
    nothing says."""
    left = max(planned - len(rows), 0)
    if left == 0:
        return 0.0, "all readings stored"
    rate, since = real_per_t_s(meta), session_start_t_s(meta)
    times = [r["t_s"] for r in rows[-RATE_READINGS - 1:] if r.get("t_s") is not None
             and r["t_s"] >= since] if rate is not None else []
    steps = [b - a for a, b in zip(times, times[1:], strict=False)]
    if steps:
        return (left * statistics.median(steps) * rate,
                f"median of the last {len(steps) + 1} readings")
    if meta.get("estimate_s") and planned:
        return left * float(meta["estimate_s"]) / planned, "the plan's estimate"
    return None, "no estimate yet"


def positions(config: dict[str, Any], last: dict[str, Any] | None) -> dict[str, float]:
    """The configured axes' positions at the last reading (degrees, as the stages reported)."""
    if last is None:
        return {}
    axes = config.get("axes", {})
    return {role: last[f"{role}_deg"] for role in MOTION_ROLES
            if role in axes and last.get(f"{role}_deg") is not None}


def status_of(run: Run, meta: dict[str, Any], rows: list[dict[str, Any]], live: Live,
              now: float) -> dict[str, Any]:
    """The /status.json document (see gonio_watch.server) of `run` as its meta.json and
    readings read now (`meta`, `rows`) say."""
    status = combined_status(meta.get("status", "unknown"), live)
    running = status not in ENDED and status != "not running"
    found = completeness_of(run, len(rows), meta)
    planned = found.planned or 0
    last = rows[-1] if rows else None
    eta, eta_from = eta_s(meta, rows, planned) if running else (None, f"run {status}")
    sample = meta.get("sample") or {}
    return {
        "run": run.path.name, "plan": meta.get("plan_name"),
        "instrument": meta.get("instrument_name"),
        "sample": sample.get("id"), "emulated": meta.get("sim"),
        "status": status, "meta_status": meta.get("status"), "reason": meta.get("reason", ""),
        "live": live.reply, "control": {"enabled": live.state is not None, "why": live.why},
        "readings": len(rows), "planned": planned,
        "incomplete": None if running or found.complete else found.text(),
        "elapsed_s": elapsed_s(meta, running, now, last["t_s"] if last else None),
        "eta_s": eta, "eta_from": eta_from,
        "positions": positions(run.config, last),
        "last": None if last is None else {k: last.get(k) for k in (
            "index", "kind", "side", "plan_theta_i_deg", "plan_theta_o_deg", "power_w")},
        "suspensions": meta.get("suspensions", []),
    }
