"""Running `gonio` on a hostile file: its exit status, its stderr and its peak memory, and the
check that it was refused as one line. The peak is the command's own maximum resident set
(getrusage of the children of a wrapper process that runs only it), counted, never timed; the
subprocess timeout only guards against a hang."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: The most memory a refused file may cost the command.
PEAK_LIMIT_MB = 500.0

#: Runs the command given as its arguments and prints its exit status, stderr and peak RSS.
_WRAPPER = """
import json, resource, subprocess, sys
proc = subprocess.run(sys.argv[1:], capture_output=True, text=True, stdin=subprocess.DEVNULL)
peak_kb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
print(json.dumps({"returncode": proc.returncode, "stderr": proc.stderr, "peak_kb": peak_kb}))
"""


@dataclass(frozen=True)
class Outcome:
    """What the command did: exit status, stderr and its peak resident memory in MB."""

    returncode: int
    stderr: str
    peak_mb: float


def gonio_measured(*args: object, hang_guard_s: float = 120.0) -> Outcome:
    """`python -m gonio_cli ARGS` in a wrapper that counts its peak memory."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run([sys.executable, "-c", _WRAPPER, sys.executable, "-m", "gonio_cli",
                           *map(str, args)], capture_output=True, text=True, cwd=ROOT, env=env,
                          timeout=hang_guard_s, check=True)
    out = json.loads(done.stdout)
    return Outcome(out["returncode"], out["stderr"], out["peak_kb"] / 1024.0)


def refused(outcome: Outcome, path: Path, problem: str) -> str:
    """Assert the command exited 2 with one `gonio VERB: error:` line naming the file and
    `problem`, no traceback, within PEAK_LIMIT_MB; returns the line."""
    lines = [ln for ln in outcome.stderr.splitlines() if ln.strip()]
    assert "Traceback" not in outcome.stderr, outcome.stderr[-2000:]
    assert outcome.returncode == 2 and len(lines) == 1, outcome.stderr[-2000:]
    assert re.match(r"gonio \w+: error: \S", lines[0]), lines[0]
    assert str(path) in lines[0] and problem in lines[0], lines[0]
    assert outcome.peak_mb < PEAK_LIMIT_MB, f"peak {outcome.peak_mb:.0f} MB"
    return lines[0]
