"""Helpers for the live view's tests and its screenshot script: their plan, a `gonio scan --sim`
in its own process (with the control token it prints), `gonio watch` beside it, and headless
Chromium (Debian's chromium and chromium-driver, driven by selenium with the driver given
explicitly, so selenium downloads nothing; a fresh profile, no background networking)."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import tempfile
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

from gonio_testkit import ROOT, fast_config, write_toml
from waiting import wait_until

CHROMIUM = Path("/usr/bin/chromium")
CHROMEDRIVER = Path("/usr/bin/chromedriver")
FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--disable-dev-shm-usage")
TOKEN_LINE = re.compile(r"gonio: control token ([0-9a-f]{32}) ")
PLAN = {"name": "watch", "sample": {"id": "w", "kind": "hemisphere", "eta": 1.51,
                                    "lit_from": "air"},
        "grid": [{"side": "reflection", "theta_i_deg": [0.0, 30.0],
                  "theta_o_deg": {"start": -70, "stop": 70, "step": 20},
                  "skip_forbidden": True},
                 {"side": "transmission", "theta_i_deg": [0.0],
                  "theta_o_deg": {"start": -40, "stop": 40, "step": 20}}],
        "dark": {"every": 8}, "beam": {"every": 8}}
"""The live view tests' plan: 28 readings (20 sample points in three panels, 4 dark, 4 beam)."""


def plan_file(folder: Path, time_scale: float | str = "inf") -> Path:
    """PLAN in folder, with its instrument (sim-serial made fast, at time_scale: about 0.5 s
    per reading at 4)."""
    write_toml(folder / "cfg.toml", fast_config(time_scale=time_scale))
    return write_toml(folder / "plan.toml", {**PLAN, "instrument": "cfg.toml"})


def missing() -> str | None:
    """Why the browser tests cannot run here (None: they can)."""
    for path in (CHROMIUM, CHROMEDRIVER):
        if not path.exists():
            return f"{path} is not installed (apt-get install chromium chromium-driver)"
    try:
        import selenium  # noqa: F401
    except ImportError:
        return "selenium is not installed (pip install 'gonio[browser]')"
    return None


@contextmanager
def chromium(width: int = 1400, height: int = 1000) -> Iterator:
    """A selenium WebDriver of headless Chromium with a window of width x height pixels."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    profile = tempfile.mkdtemp(prefix="gonio-chromium-")
    options = webdriver.ChromeOptions()
    options.binary_location = str(CHROMIUM)
    for flag in (*FLAGS, f"--user-data-dir={profile}", f"--window-size={width},{height}"):
        options.add_argument(flag)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(service=Service(str(CHROMEDRIVER)), options=options)
    try:
        yield driver
    finally:
        driver.quit()
        shutil.rmtree(profile, ignore_errors=True)


def _env() -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": str(ROOT)}


@dataclass
class Scan:
    """A `gonio scan` process, its run directory once made, and its stderr lines so far."""

    proc: subprocess.Popen
    run_dir: Path | None = None
    stderr: list[str] = field(default_factory=list)

    def token(self) -> str | None:
        """The session's control token, from the line the scan printed (None: none)."""
        for line in self.stderr:
            if found := TOKEN_LINE.search(line):
                return found.group(1)
        return None

    def stored(self) -> int:
        """Complete lines in readings.jsonl now."""
        return (self.run_dir / "readings.jsonl").read_bytes().count(b"\n")


@contextmanager
def scanning(plan: Path, out: Path, *options: str, timeout: float = 120.0) -> Iterator[Scan]:
    """`gonio scan PLAN --sim --out OUT OPTIONS` in its own process, yielded once its run
    directory exists; stopped by SIGTERM if still running at the end."""
    proc = subprocess.Popen([sys.executable, "-m", "gonio_cli", "scan", str(plan), "--sim",
                             "--out", str(out), "--no-plot", "--no-progress", *options],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=_env())
    scan = Scan(proc)
    threading.Thread(target=lambda: scan.stderr.extend(proc.stderr), daemon=True).start()
    try:
        made = wait_until(lambda: [p.parent for p in out.glob("*/meta.json")]
                          or proc.poll() is not None, timeout, "the run directory")
        assert made is not True, f"no run directory; stderr: {''.join(scan.stderr)}"
        scan.run_dir = made[0]
        yield scan
    finally:
        if proc.poll() is None:
            proc.terminate()
        proc.wait(timeout=60)


@contextmanager
def watching(run_dir: Path, token: str | None = None) -> Iterator[str]:
    """`gonio watch RUN_DIR [--token -]` in its own process (the token on its stdin); yields
    the page's URL; stopped by SIGTERM at the end."""
    proc = subprocess.Popen([sys.executable, "-m", "gonio_cli", "watch", str(run_dir),
                             *(["--token", "-"] if token else [])],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                            env=_env())
    try:
        if token:
            proc.stdin.write(token + "\n")
            proc.stdin.flush()
        url = proc.stdout.readline().strip()
        assert url.startswith("http://127.0.0.1:"), url
        yield url
    finally:
        proc.terminate()
        assert proc.wait(timeout=30) == 0


def page_counts(driver) -> tuple[int, int, str]:
    """(the page's stored count, points in its raw plot, its status), read at one moment."""
    readings, points, status = driver.execute_script(
        "return [document.getElementById('readings').textContent,"
        " document.querySelectorAll('#raw-plot .pt').length,"
        " document.getElementById('status').textContent]")
    return int(readings), int(points), status


def open_page(driver, url: str) -> None:
    """Load the page with room to count its polls (the resource timing buffer holds 250
    entries by default: four minutes of polling)."""
    driver.get(url)
    driver.execute_script("performance.setResourceTimingBufferSize(100000)")


def page_clock(driver) -> float:
    """The page's clock now (performance.now(), ms): a mark to count polls from."""
    return driver.execute_script("return performance.now()")


def polls_since(driver, mark_ms: float) -> int:
    """The page's polls (its /status.json fetches) started after mark_ms and answered."""
    return driver.execute_script(
        "return performance.getEntriesByType('resource').filter(e => e.startTime > arguments[0]"
        " && new URL(e.name).pathname === '/status.json').length", mark_ms)
