"""The reduced BSDF of the readings stored so far, as `gonio reduce` computes it
(calibration.pipeline.reduce_stored), redone when readings arrive (at most once a second) and
kept per reading with the version at which its value last changed, so a page that has
version V fetches only the points that changed since (all of them once a new beam or dark
reading moves the normalisation). A partial run that cannot be reduced yet (no beam reading,
fewer than two dark readings) is a state with its reason, not an error."""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from calibration.pipeline import reduce_stored
from calibration.plot import in_plane, panel_limits, signed_theta_o_deg, x_range
from calibration.reduced import ReducedData
from gonio.config import parse_config
from gonio.errors import GonioError
from gonio.plan import build_schedule, parse_plan
from gonio.store import Run, readings_array

MIN_INTERVAL_S = 1.0  # between two reductions of a growing run
DARK_LIMITED = "dark-limited"  # an invalid point that is neither saturated nor otherwise flagged
SIDES = ("reflection", "transmission")


def panel_key(theta_i_deg: float, side: str) -> str:
    """A figure panel's name: the incidence (0.1 deg) and side, e.g. "30|reflection"."""
    return f"{theta_i_deg:g}|{side}"


def _number(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def point_flags(reduced_flags: str, reading: dict[str, Any], valid: bool) -> list[str]:
    """Why a point is marked: reduction's flags (signature, horizon), the reading's own
    (saturated, retried), and dark-limited for an invalid point nothing else explains."""
    flags = [f for f in reduced_flags.split(",") if f]
    flags += ["saturated"] * bool(reading.get("saturated"))
    flags += [f for f in (reading.get("flags") or "").split(",") if f]
    if not valid and not flags:
        flags.append(DARK_LIMITED)
    return flags


def points_of(data: ReducedData, by_index: dict[int, dict[str, Any]]
              ) -> dict[int, dict[str, Any]]:
    """The in-plane reduced points, by the index of the reading each comes from."""
    shown = in_plane(data)
    theta_i = np.round(data.theta_i_deg, 1)
    theta_o = signed_theta_o_deg(data)
    out = {}
    for j in np.flatnonzero(shown):
        index = int(data.meta["index"][j])
        side = "transmission" if data.transmission[j] else "reflection"
        valid = bool(data.valid[j])
        out[index] = {"i": index, "key": panel_key(float(theta_i[j]), side),
                      "x": float(theta_o[j]), "f": _number(data.bsdf[j]),
                      "s": _number(data.sigma[j]), "valid": valid,
                      "flags": point_flags(str(data.flags[j]), by_index[index], valid)}
    return out


def planned_angles(run: Run) -> dict[str, np.ndarray]:
    """The plan's in-plane outgoing angles per panel, from the run's schedule (the plan's
    angles have the figures' sign: forward > 0); {} if the schedule cannot be built."""
    try:
        schedule = build_schedule(parse_plan(run.plan, run.path / "plan.toml"),
                                  parse_config(run.config, run.path / "instrument.toml"))
    except GonioError:
        return {}
    rows = schedule.readings[schedule.readings["kind"] == "sample"]
    rows = rows[np.abs(np.sin(np.radians(rows["phi_o_deg"]))) < 1e-9]
    keys = [panel_key(round(float(t), 1), str(side))
            for t, side in zip(rows["theta_i_deg"], rows["side"], strict=True)]
    return {key: rows["theta_o_deg"][[k == key for k in keys]] for key in set(keys)}


def panels_of(points: dict[int, dict[str, Any]], planned: dict[str, np.ndarray]
              ) -> list[dict[str, Any]]:
    """One figure panel per (incidence, side) with points: reflection first, incidences
    rising, each with its axis ranges (calibration.plot.panel_limits, as `gonio plot` draws
    them; while a panel still lacks planned points, its outgoing angles span the planned
    ones, so the axis stays put as they come)."""
    keys = sorted({p["key"] for p in points.values()},
                  key=lambda k: (SIDES.index(k.split("|")[1]), float(k.split("|")[0])))
    panels = []
    for key in keys:
        mine = [p for p in points.values() if p["key"] == key]
        x = np.array([p["x"] for p in mine])
        f = np.array([np.nan if p["f"] is None else p["f"] for p in mine])
        good = np.array([p["valid"] for p in mine]) & (np.nan_to_num(f) > 0)
        x_lim, y_lim = panel_limits(x, f, good)
        if len(mine) < len(planned.get(key, ())):
            x_lim = x_range(planned[key])
        theta_i, side = key.split("|")
        panels.append({"key": key, "theta_i_deg": float(theta_i), "side": side,
                       "x": list(x_lim), "y": None if y_lim is None else list(y_lim),
                       "points": len(mine), "valid": int(good.sum())})
    return panels


class LiveReduction:
    """The reduction of a run's readings so far, versioned per point (thread-safe)."""

    def __init__(self, run: Run, reduce: Callable[[Run, np.ndarray], ReducedData] | None = None,
                 clock: Callable[[], float] = time.monotonic):
        """reduce: how to reduce (default `gonio reduce`'s, with the run's calibration)."""
        self.run = run
        self._reduce = reduce or reduce_stored
        self._clock = clock
        self._lock = threading.Lock()
        self._count, self._at = -1, -math.inf
        self.state, self.reason, self.meta = "waiting", "no readings yet", None
        self.version = self._reset_version = 0
        self._points: dict[int, dict[str, Any]] = {}
        self._changed: dict[int, int] = {}
        self._out_of_plane = 0
        self._planned = planned_angles(run)

    def update(self, rows: list[dict[str, Any]]) -> None:
        """Reduce `rows` (the readings stored so far) unless their number is the one last
        reduced or the last reduction is under MIN_INTERVAL_S old."""
        with self._lock:
            if len(rows) == self._count or self._clock() - self._at < MIN_INTERVAL_S:
                return
            self._count, self._at = len(rows), self._clock()
            if not rows:
                return
            rows = sorted(rows, key=lambda r: r["index"])
            try:
                data = self._reduce(self.run, readings_array(rows))
            except GonioError as exc:
                self._not_reducible(str(exc))
                return
            points = points_of(data, {r["index"]: r for r in rows})
            changed = {i for i, p in points.items() if self._points.get(i) != p}
            if changed:
                self.version += 1
                self._changed.update(dict.fromkeys(changed, self.version))
                self._points.update((i, points[i]) for i in changed)
            self.state, self.reason, self.meta = "reduced", "", data.meta
            self._out_of_plane = len(data.bsdf) - len(points)

    def _not_reducible(self, reason: str) -> None:
        self.state, self.reason = "not yet reducible", reason
        if self._points:  # what was drawn no longer stands: every page starts again
            self.version += 1
            self._reset_version = self.version
            self._points, self._changed = {}, {}

    def since(self, version: int) -> dict[str, Any]:
        """The reduction for a page that has `version` of it: the points changed since (all
        of them, with replace true, when what it has no longer stands)."""
        with self._lock:
            replace = version < self._reset_version
            points = [self._points[i] for i, v in self._changed.items()
                      if replace or v > version]
            meta = self.meta or {}
            return {"state": self.state, "reason": self.reason, "version": self.version,
                    "replace": replace, "readings": max(self._count, 0), "points": points,
                    "panels": panels_of(self._points, self._planned),
                    "out_of_plane": self._out_of_plane,
                    "noise_model": meta.get("noise_model"),
                    "aperture_from": meta.get("aperture_from")}

    def reduced_meta(self) -> dict[str, Any] | None:
        """The last reduction's meta (the model curves need its aperture and [sim])."""
        with self._lock:
            return self.meta
