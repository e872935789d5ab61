"""Scans killed and terminated at random, resumed until complete, checked: nothing lost.

Soak: N scans on the two-process bench (the emulators served from this process as `gonio
emulate` serves them, each `gonio scan` in a process of its own) with random reply faults at a
stated rate, each ended by SIGKILL or SIGTERM at random moments and resumed (`gonio scan
--resume RUN`) until completed, then `gonio check` on each. Beside it, in the same run, its
baseline: the same scans (same emulator config and faults) uninterrupted.

It prints the readings planned and stored; lost (stored before an ending, missing or changed
after: must be 0) and duplicated (0); damaged lines detected (0: a kill may tear only the last
line, cut on resume); axes left moving after a catchable ending (SIGTERM: each ESP axis asked
`MD?` once the stop's deceleration is over; must be 0; SIGKILL cannot be caught, so axes it
leaves moving are shown but not counted); that the SIGTERM endings were recorded as aborted
with reason SIGTERM and exit 143; that the finished runs' indices and stage positions match
the baseline's; and the time of both.

The live view under load, in the same run: each scan once more uninterrupted with `gonio scan
--watch`, its viewer polled by --pages pages (as watch.js polls, with the key's cookie) and
held by --idle idle connections against its connection cap, from the moment it prints its
URL (held paused until then); and a quiet scan (instant motion, no faults, ~3,000
readings) without and with that load. It prints the readings lost under load (must be 0),
the pages' polls answered, and each pair's readings per second over the middle of the scan
(20 % to 90 % of its readings).

Run: python bench/soak.py [--scans 6] [--seed 0] [--fault-rate 0.005] [--time-scale 20]
                          [--pages 20] [--idle 1000]
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import serial

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "tests" / "gonio"), str(ROOT / "tests")]  # gonio_testkit, waiting
from _viewer_load import IdleConnections, Pages  # noqa: E402
from gonio_testkit import fast_config, pointed, token_of, write_plan, write_toml  # noqa: E402

from gonio.config import load_config  # noqa: E402
from gonio.simulate import serve  # noqa: E402
from gonio.store import open_run  # noqa: E402
from gonio_watch.control import ControlChannel  # noqa: E402

ENV = {**os.environ, "PYTHONPATH": str(ROOT)}
POSITIONS = ("sample_deg", "arm_deg")
ESP_AXES = (1, 2)  # sample, arm (sim-serial)
MAX_SESSIONS = 30
FAULTS = ("drop_prob", "corrupt_prob", "stall_prob")  # transient: a retry gets past them
PACE_S = 0.05  # between two counts of a scan's stored readings
MIDDLE = (0.2, 0.9)  # the share of a scan's readings its rate is measured between
QUIET_PLAN = {"name": "quiet", "dark": {"every": 200}, "grid": [
    {"side": "reflection", "theta_i_deg": [0.0, 20.0, 40.0, 60.0],
     "theta_o_deg": {"start": -80.0, "stop": 80.0, "step": 0.2}, "skip_forbidden": True}]}


@dataclass
class Tally:
    """What the soak counts over every scan."""

    planned: int = 0
    stored: int = 0
    lost: int = 0
    duplicated: int = 0
    damaged: int = 0
    torn: int = 0
    endings: dict[str, int] = field(default_factory=lambda: {"SIGKILL": 0, "SIGTERM": 0})
    failed_sessions: int = 0  # a fault beyond the retries: resumed like the others
    sigterm_recorded: int = 0
    moving_after_sigterm: int = 0
    moving_after_sigkill: int = 0
    checks_clean: int = 0
    mismatched: int = 0  # finished runs whose indices or positions differ from the baseline's
    faults: int = 0  # injected (most the drivers get past within a request)
    seconds: float = 0.0
    baseline_seconds: float = 0.0
    viewed_planned: int = 0  # the scans beside a loaded viewer
    viewed_lost: int = 0
    viewed_clean: int = 0
    polls: int = 0  # the pages' polls answered, refused (not 200), failed (no answer)
    polls_refused: int = 0
    polls_failed: int = 0
    idle_closed: int = 0  # idle connections the viewer closed (cap, deadline)
    rates: dict[str, list[float]] = field(default_factory=dict)  # readings/s by pass
    quiet_planned: int = 0


class Pace:
    """Counts a scan's stored readings every PACE_S on a thread of its own, for its rate."""

    def __init__(self, runs: Path):
        self.samples: list[tuple[float, int]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._count, args=(runs,), daemon=True)
        self._thread.start()

    def _count(self, runs: Path) -> None:
        while not self._stop.wait(PACE_S):
            self.samples.append((time.perf_counter(), lines_in(runs)[0]))

    def rate(self, planned: int, since: float = 0.0) -> float:
        """Readings per second between MIDDLE's shares of `planned` (from `since` on)."""
        self._stop.set()
        self._thread.join()
        low, high = (share * planned for share in MIDDLE)
        middle = [(t, n) for t, n in self.samples if t >= since and low <= n <= high]
        (t0, n0), (t1, n1) = middle[0], middle[-1]
        return (n1 - n0) / (t1 - t0)


def gonio(*args: object) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "gonio_cli", *map(str, args)], env=ENV,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


class Emulator:
    """The emulated devices of a config served from this process, as `gonio emulate` serves
    them (the scans run in processes of their own); asked over the pty whether the ESP moves."""

    def __init__(self, config: Path):
        self.bench = serve(load_config(config))
        self.endpoints = {n: (e.protocol, e.endpoint) for n, e in self.bench.endpoints.items()}

    def moving_axes(self) -> int:
        """How many ESP axes report motion not done (MD? 0)."""
        with serial.Serial(self.endpoints["esp"][1], 19200, timeout=2) as port:
            port.reset_input_buffer()
            moving = 0
            for axis in ESP_AXES:
                port.write(b"%dMD?\r" % axis)
                moving += port.readline().strip() == b"0"
            return moving

    def faults(self) -> int:
        """Faults injected so far, over every device and kind."""
        return sum(sum(kinds.values()) for kinds in self.bench.fault_counts().values())

    def close(self) -> None:
        self.bench.stop()


def lines_in(runs: Path) -> tuple[int, Path | None]:
    found = list(runs.glob("*/readings.jsonl"))
    return (found[0].read_bytes().count(b"\n"), found[0].parent) if found else (0, None)


def snapshot(run_dir: Path) -> tuple[dict[int, str], int, int]:
    """The stored readings (index -> canonical JSON), damaged lines, torn tail bytes."""
    lines = open_run(run_dir).lines()
    rows = {r["index"]: json.dumps(r, sort_keys=True) for r in lines.rows}
    return rows, len(lines.damaged), lines.torn_bytes


def scan_args(plan: Path, runs: Path, run_dir: Path | None) -> list[object]:
    start = ["--resume", run_dir] if run_dir else [plan, "--out", runs]
    return ["scan", *start, "--no-plot", "--no-progress"]


def interrupted_chain(plan: Path, runs: Path, emu: Emulator, planned: int, time_scale: float,
                      rng: np.random.Generator, tally: Tally) -> Path:
    """Run the scan, end it by SIGKILL or SIGTERM at 1-3 random moments, resume until it is
    completed; count what the endings did. Returns the run directory."""
    kills = sorted(rng.choice(np.arange(1, planned - 5), size=rng.integers(1, 4), replace=False))
    seen: dict[int, str] = {}
    run_dir = None
    decelerate_s = 30.0 / 120.0  # the arm's speed / acceleration (sim-serial), virtual
    for _ in range(MAX_SESSIONS):
        proc = gonio(*scan_args(plan, runs, run_dir))
        ending = kills.pop(0) if kills else None
        while ending is not None and lines_in(runs)[0] < ending and proc.poll() is None:
            time.sleep(0.002)
        sig = None
        if ending is not None and proc.poll() is None:
            time.sleep(rng.uniform(0.0, 0.2))
            sig = signal.SIGKILL if rng.random() < 0.5 else signal.SIGTERM
            proc.send_signal(sig)
        out, _ = proc.communicate(timeout=600)
        run_dir = run_dir or lines_in(runs)[1]
        meta = open_run(run_dir).meta
        if sig is not None and proc.returncode in (-signal.SIGKILL, 128 + signal.SIGTERM):
            tally.endings[sig.name] += 1
            time.sleep(decelerate_s / time_scale + 0.1)
            moving = emu.moving_axes()
            if sig == signal.SIGTERM:
                tally.moving_after_sigterm += moving
                recorded = (meta["status"], meta["reason"]) == ("aborted", "SIGTERM")
                tally.sigterm_recorded += recorded
                if not recorded:
                    print(f"soak: {run_dir.name}: a SIGTERM ending recorded as "
                          f"{meta['status']}: {meta['reason']}", file=sys.stderr)
            else:
                tally.moving_after_sigkill += moving
        elif meta["status"] == "failed":
            tally.failed_sessions += 1
        rows, damaged, torn = snapshot(run_dir)
        tally.damaged += damaged
        tally.torn += torn > 0
        tally.lost += sum(rows.get(i) != line for i, line in seen.items())
        seen.update(rows)
        if meta["status"] == "completed":
            return run_dir
    raise RuntimeError(f"{run_dir}: not completed after {MAX_SESSIONS} sessions")


def readings_of(run_dir: Path) -> np.ndarray:
    return open_run(run_dir).readings()


def one_scan(k: int, folder: Path, args: argparse.Namespace, tally: Tally) -> None:
    """Scan k: its baseline, then the interrupted chain; compare, check, count."""
    rng = np.random.default_rng([args.seed, k])
    faults = {dev: {**dict.fromkeys(FAULTS, args.fault_rate), "seed": args.seed * 100 + k}
              for dev in ("esp", "pm100")}
    cfg = fast_config(time_scale=args.time_scale, faults=faults, esp={"timeout_s": 0.3},
                      pm100={"timeout_s": 0.5})
    cfg["sim"]["seed"] = args.seed * 100 + k
    plan = {"name": f"soak{k}", "dark": {"every": 20}, "grid": [
        {"side": "reflection", "theta_i_deg": [float(t) for t in rng.choice([10, 30, 50], 2)],
         "theta_o_deg": {"start": -80.0, "stop": 80.0, "step": float(rng.choice([5, 8]))},
         "skip_forbidden": True}]}
    emulated = write_toml(folder / f"emulated{k}.toml", cfg)
    results = {}
    for name in ("baseline", "soak"):
        emu = Emulator(emulated)
        try:
            plan_path = write_plan(folder, plan, pointed(cfg, emu.endpoints), name=f"{name}{k}")
            runs = folder / f"{name}{k}-runs"
            t0 = time.perf_counter()
            if name == "baseline":
                run_dir = uninterrupted(plan_path, runs, "baseline", tally)
                tally.baseline_seconds += time.perf_counter() - t0
            else:
                planned = open_run(results["baseline"]).meta["planned"]
                run_dir = interrupted_chain(plan_path, runs, emu, planned, args.time_scale,
                                            rng, tally)
                tally.seconds += time.perf_counter() - t0
                tally.faults += emu.faults()
            results[name] = run_dir
        finally:
            emu.close()
    run = open_run(results["soak"])
    lines = run.lines()
    tally.planned += run.meta["planned"]
    tally.stored += len(lines.rows)
    tally.duplicated += lines.count - len({r["index"] for r in lines.rows})
    tally.lost += run.meta["planned"] - len(lines.rows)
    check = gonio("check", results["soak"])
    check.communicate(timeout=120)
    tally.checks_clean += check.returncode == 0
    tally.mismatched += not same_readings(results["baseline"], results["soak"])
    emu = Emulator(emulated)
    try:
        plan_path = write_plan(folder, plan, pointed(cfg, emu.endpoints), name=f"viewed{k}")
        viewed = watched(plan_path, folder / f"viewed{k}-runs", "viewed", args, tally)
    finally:
        emu.close()
    tally.mismatched += not same_readings(results["baseline"], viewed)


def same_readings(reference: Path, other: Path) -> bool:
    """Whether two runs stored the same indices at the same stage positions."""
    ref, got = readings_of(reference), readings_of(other)
    return len(ref) == len(got) and (ref["index"] == got["index"]).all() and all(
        np.allclose(ref[f], got[f], atol=1e-3) for f in POSITIONS)


def uninterrupted(plan: Path, runs: Path, name: str, tally: Tally) -> Path:
    """Scan without a viewer; its rate goes to tally.rates[name]."""
    pace = Pace(runs)
    proc = gonio(*scan_args(plan, runs, None))
    proc.communicate(timeout=600)
    run_dir = lines_in(runs)[1]
    run = open_run(run_dir)
    assert run.status == "completed", run_dir
    tally.rates.setdefault(name, []).append(pace.rate(run.meta["planned"]))
    return run_dir


def watched(plan: Path, runs: Path, name: str, args: argparse.Namespace, tally: Tally) -> Path:
    """Scan with `--watch`, held paused (its control channel) until its viewer is loaded by
    args.pages pages and args.idle idle connections; count what was lost, the polls, the
    rate under load (tally.rates[name])."""
    pace = Pace(runs)
    proc = gonio(*scan_args(plan, runs, None), "--watch")
    token, run_dir = token_of(proc)
    channel = ControlChannel(Path(run_dir), token)
    assert channel.request("pause")["ok"]
    url = next(line.split()[-1] for line in proc.stderr if line.startswith("gonio scan: watch "))
    threading.Thread(target=proc.stderr.read, daemon=True).start()
    idle = IdleConnections(url, args.idle)
    pages = Pages(url, args.pages)
    loaded = time.perf_counter()
    assert channel.request("resume")["ok"]
    proc.stdout.read()
    proc.wait(timeout=600)
    pages.close()
    idle.close()
    run = open_run(run_dir)
    tally.viewed_planned += run.meta["planned"]
    tally.viewed_lost += run.meta["planned"] - len(run.lines().rows)
    check = gonio("check", run_dir)
    check.communicate(timeout=120)
    tally.viewed_clean += check.returncode == 0
    tally.polls += pages.counts["polls"]
    tally.polls_refused += pages.counts["refused"]
    tally.polls_failed += pages.counts["failed"]
    tally.idle_closed += idle.closed_by_viewer
    tally.rates.setdefault(name, []).append(pace.rate(run.meta["planned"], since=loaded))
    return Path(run_dir)


def quiet_pair(folder: Path, args: argparse.Namespace, tally: Tally) -> None:
    """The quiet scan (instant motion, no faults) without the viewer and beside a loaded one."""
    cfg = fast_config(time_scale="inf")
    emulated = write_toml(folder / "emulated-quiet.toml", cfg)
    for name in ("quiet", "quiet viewed"):
        emu = Emulator(emulated)
        try:
            plan = write_plan(folder, QUIET_PLAN, pointed(cfg, emu.endpoints),
                              name=name.replace(" ", "-"))
            runs = folder / f"{name.replace(' ', '-')}-runs"
            if name == "quiet":
                run_dir = uninterrupted(plan, runs, name, tally)
                tally.quiet_planned = open_run(run_dir).meta["planned"]
            else:
                watched(plan, runs, name, args, tally)
        finally:
            emu.close()


def main() -> None:
    """Run the scans, print the figures beside the baseline."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scans", type=int, default=6)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--fault-rate", type=float, default=0.005,
                        help="per reply, each of: a dropped byte, a corrupted byte, a stall")
    parser.add_argument("--time-scale", type=float, default=20.0,
                        help="the emulators' virtual seconds per real second")
    parser.add_argument("--pages", type=int, default=20,
                        help="pages polling the live view beside a scan")
    parser.add_argument("--idle", type=int, default=1000,
                        help="idle connections held against the live view's cap")
    args = parser.parse_args()
    if args.scans < 1 or not 0.0 <= args.fault_rate <= 1.0 or not args.time_scale > 0 \
            or args.pages < 1 or args.idle < 0:
        parser.error("--scans must be >= 1, --fault-rate in [0, 1], --time-scale > 0, "
                     "--pages >= 1, --idle >= 0")
    load = " ".join(f"{x:.2f}" for x in os.getloadavg())
    tally = Tally()
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(args.scans):
            one_scan(k, Path(tmp), args, tally)
        quiet_pair(Path(tmp), args, tally)
    t = tally
    endings = t.endings["SIGKILL"] + t.endings["SIGTERM"]
    print(f"soak: {args.scans} scans (sim-serial, two processes, time scale {args.time_scale:g}), "
          f"seed {args.seed}, faults per reply: drop, corrupt, stall {args.fault_rate:g} each; "
          f"load average {load}")
    print(f"  endings: {endings} ({t.endings['SIGKILL']} SIGKILL, {t.endings['SIGTERM']} "
          f"SIGTERM) at random moments, {t.failed_sessions} sessions failed on faults beyond "
          f"the retries; {t.faults} faults injected; every run resumed until completed")
    print(f"  readings planned {t.planned}, stored {t.stored}, lost {t.lost}, "
          f"duplicated {t.duplicated}")
    print(f"  damaged lines detected {t.damaged} (torn last lines cut on resume: {t.torn}); "
          f"gonio check clean: {t.checks_clean}/{args.scans}")
    print(f"  axes left moving after a catchable ending (SIGTERM): {t.moving_after_sigterm}; "
          f"SIGTERM recorded as aborted/SIGTERM, exit 143: {t.sigterm_recorded}/"
          f"{t.endings['SIGTERM']}; (after SIGKILL, not catchable: {t.moving_after_sigkill})")
    print(f"  indices and stage positions as the baseline's: {args.scans - t.mismatched}/"
          f"{args.scans} runs")
    print(f"{'':2}{'what':<46}{'seconds':>9}")
    print(f"  {'baseline: the same scans uninterrupted':<46}{t.baseline_seconds:>9.1f}")
    print(f"  {'soak: interrupted and resumed until completed':<46}{t.seconds:>9.1f}")
    print(f"  viewer: {args.pages} pages polling and {args.idle} idle connections on each "
          f"`gonio scan --watch`: readings planned {t.viewed_planned}, lost {t.viewed_lost}; "
          f"gonio check clean: {t.viewed_clean}/{args.scans + 1}; polls answered {t.polls}, "
          f"refused {t.polls_refused}, unanswered {t.polls_failed} (closed before their "
          f"request was read: the cap's churn; asked again a second later); idle connections "
          f"the viewer closed {t.idle_closed}")
    low, high = (f"{share:.0%}" for share in MIDDLE)
    print(f"  {f'readings/s ({low}-{high} of each scan, median)':<46}{'without':>9}"
          f"{'with viewer load':>18}")
    for what, without, with_load in (
            (f"the soak's scans (time scale {args.time_scale:g}, faults)", "baseline", "viewed"),
            (f"a quiet scan (instant motion, {t.quiet_planned} readings)", "quiet",
             "quiet viewed")):
        print(f"  {what:<46}{np.median(t.rates[without]):>9.1f}"
              f"{np.median(t.rates[with_load]):>18.1f}")


if __name__ == "__main__":
    main()
