"""Readings per second of a gonio plan under Bluesky's RunEngine, beside gonio's own engine.

One in-plane plan on the emulated serial bench (sim-serial, instant motion, zero latency) is
measured twice in one process, each time on freshly started emulators: by `gonio scan`'s
path (gonio.runner.new_scan: engine, run store with an fsync per reading) and by
`gonio.bluesky.plan` on `gonio.bluesky.devices` under a RunEngine (documents kept in memory
by a subscriber). Both run twice, alternating, and the second round is reported, so that
neither pays alone for the emulated bench's first-use tables. The rate is over the measuring
loop, first reading to last (the stored `t_s`, the events' `time`): start-up is not counted.

Run: python bench/bluesky_plan.py [--points 400]
"""

from __future__ import annotations

import argparse
import math
import tempfile
import time
import tomllib
from pathlib import Path

from bluesky import RunEngine
from scan_throughput import config_text, load, plan_text

from gonio.bluesky import devices, plan
from gonio.config import parse_config
from gonio.plan import build_schedule, parse_plan
from gonio.runner import new_scan
from gonio.store import open_run


def loop_rate(times: list[float]) -> float:
    """Readings per second from the first reading's time to the last."""
    return (len(times) - 1) / (max(times) - min(times))


def gonio_engine(plan_path: Path, out: Path) -> tuple[int, float]:
    """(readings, readings/s) of the plan by gonio scan --sim's path."""
    result = new_scan(plan_path, sim=True, out=out, progress=False)
    rows = open_run(result.path).rows()
    return len(rows), loop_rate([row["t_s"] for row in rows])


def run_engine(plan_path: Path, config_path: Path) -> tuple[int, float]:
    """(events, events/s) of the plan under Bluesky's RunEngine."""
    RE = RunEngine()
    times: list[float] = []
    RE.subscribe(lambda name, doc: times.append(doc["time"]) if name == "event" else None)
    with devices(config_path, sim=True) as d:
        RE(plan(plan_path, d))
    return len(times), loop_rate(times)


def main() -> None:
    """Measure both, print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=400)
    args = parser.parse_args()
    load_before = load()
    per_curve = math.ceil(args.points / 10)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        (folder / "instrument.toml").write_text(config_text())
        (folder / "plan.toml").write_text(plan_text(per_curve))
        n = len(build_schedule(parse_plan(tomllib.loads(plan_text(per_curve))),
                               parse_config(tomllib.loads(config_text()))))
        for _ in range(2):  # the second round: the bench's caches warm for both alike
            t = time.perf_counter()
            n_gonio, gonio_rate = gonio_engine(folder / "plan.toml", folder / "runs")
            gonio_wall = time.perf_counter() - t
            t = time.perf_counter()
            n_bluesky, bluesky_rate = run_engine(folder / "plan.toml",
                                                 folder / "instrument.toml")
            bluesky_wall = time.perf_counter() - t
    assert n_gonio == n_bluesky == n, (n, n_gonio, n_bluesky)
    print(f"a plan of {n} readings (sim-serial, instant motion, zero latency); load average "
          f"{load_before} before, {load()} after")
    print(f"  {'what':<58}{'ms/reading':>11}{'readings/s':>11}{'wall s':>8}")
    for what, rate, wall in (("baseline: gonio's engine (gonio scan --sim, fsync each)",
                              gonio_rate, gonio_wall),
                             ("gonio.bluesky.plan under a RunEngine", bluesky_rate,
                              bluesky_wall)):
        print(f"  {what:<58}{1e3 / rate:>11.3f}{rate:>11.0f}{wall:>8.1f}")
    print(f"  RunEngine / gonio engine, time per reading: {gonio_rate / bluesky_rate:.2f}x")


if __name__ == "__main__":
    main()
