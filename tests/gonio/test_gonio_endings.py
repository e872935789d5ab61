"""Every ending of a scan is recorded, whatever its moment (real `gonio scan` processes, each
acting at an exact point through scan_at_points.py): a SIGTERM or SIGHUP the moment the run
directory appears ends the run as aborted with why, prints its path, and the run resumes; a run
directory made immutable mid-scan says in one line that its end is not recorded and where the
readings are (the control socket it cannot remove hides nothing), and it is recorded once the
directory takes writes; a signal after an abort leaves the abort's exit code and path."""

import json
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from gonio_testkit import ROOT, fast_config, gonio_cli, run_dir_of, scan_messages, write_plan

from gonio.store import open_run

PLAN = {"name": "ends", "grid": [{"theta_i_deg": [0.0], "theta_o_deg": [10.0, 80.0, 20.0, 85.0]}]}
DRIVER = Path(__file__).with_name("scan_at_points.py")
START_SESSION = {"at": "open", "match": r"-ends/meta\.json\.tmp$"}  # meta.json says running
CLOSE_DEVICES = {"at": "call", "match": r"gonio/instrument\.py:close_all$"}


def default_signals() -> None:
    """The scan's signals at their defaults, as in a terminal's foreground job: a suite run
    under nohup, or as a background job, passes them on ignored, and the scan keeps a signal
    ignored on entry (gonio.run_control)."""
    for sig in (signal.SIGHUP, signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.SIG_DFL)


def scan_at(tmp_path: Path, steps: list[dict]) -> subprocess.CompletedProcess:
    """`gonio scan PLAN --sim` into tmp_path/runs, taking `steps` (scan_at_points.py); every
    step is checked to have been taken."""
    steps_file = tmp_path / "steps.json"
    steps_file.write_text(json.dumps(steps))
    plan = write_plan(tmp_path, PLAN, fast_config())
    proc = subprocess.run([sys.executable, str(DRIVER), str(steps_file), "scan", str(plan),
                           "--sim", "--out", str(tmp_path / "runs"), "--no-plot",
                           "--no-progress"], capture_output=True, text=True, cwd=ROOT,
                          env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=120,
                          stdin=subprocess.DEVNULL, preexec_fn=default_signals)
    taken = steps_file.with_name("steps.json.taken")
    assert taken.exists() and len(taken.read_text().split()) == len(steps), proc.stderr
    assert "Traceback" not in proc.stderr, proc.stderr
    return proc


def only_run(proc: subprocess.CompletedProcess, runs: Path) -> Path:
    """The run directory the scan printed last, the only entry under `runs`."""
    run_dir = run_dir_of(proc)
    assert [p.name for p in runs.iterdir()] == [run_dir.name]  # no .partial left behind
    return run_dir


@pytest.mark.parametrize(("sig", "point"), [
    ("SIGTERM", {"at": "open", "match": r"/runs$"}),  # renamed into place, not yet fsynced
    ("SIGTERM", {"at": "shutil.rmtree", "match": r"/\.partial/"}),  # the maker's clean-up
    ("SIGHUP", {"at": "open", "match": r"-ends/readings\.jsonl$"}),  # the writer takes its lock
    ("SIGHUP", {"at": "socket.bind", "match": r"control\.sock$"}),  # the control channel
], ids=["renamed", "cleaning-up", "locking", "channel"])
def test_a_signal_as_the_run_directory_appears_is_its_recorded_end(tmp_path, sig, point):
    proc = scan_at(tmp_path, [{"do": sig, **point}])
    signum = getattr(signal, sig)
    assert proc.returncode == 128 + signum, proc.stderr
    run_dir = only_run(proc, tmp_path / "runs")
    run = open_run(run_dir)
    reason = f"{sig} before the run's first reading"
    assert (run.meta["status"], run.meta["reason"]) == ("aborted", reason)
    assert scan_messages(proc.stderr)[-1] == f"gonio scan: run aborted after 0 readings: {reason}"
    resumed = gonio_cli("scan", "--resume", run_dir, "--no-plot", "--no-progress")
    assert resumed.returncode == 0, resumed.stderr
    run = open_run(run_dir)
    assert run.meta["status"] == "completed" and len(run) == run.meta["planned"] == 4


def chattr_works(folder: Path) -> bool:
    """Whether `chattr +i` makes a folder here refuse new files (root, a filesystem that
    keeps the flag); the folder is left as it was."""
    probe = folder / "probe"
    probe.mkdir()
    if shutil.which("chattr") is None or subprocess.run(
            ["chattr", "+i", probe], capture_output=True).returncode:
        return False
    try:
        (probe / "x").touch()
    except PermissionError:
        return True
    finally:
        subprocess.run(["chattr", "-i", probe], check=True)
    return False


def test_a_run_directory_made_immutable_mid_scan_says_its_end_is_not_recorded(tmp_path):
    if not chattr_works(tmp_path):
        pytest.skip("chattr +i does not make a folder refuse writes here (needs root and a "
                    "filesystem that keeps the immutable flag)")
    runs = tmp_path / "runs"
    try:
        proc = scan_at(tmp_path, [{"do": "immutable", "paths": str(runs / "*-ends"),
                                   "at": "call", "match": r"gonio/store\.py:append$", "nth": 2}])
    finally:
        for run_dir in runs.glob("*-ends"):
            subprocess.run(["chattr", "-i", run_dir], check=True)
    run_dir = run_dir_of(proc)
    assert proc.returncode == 1, proc.stderr
    assert scan_messages(proc.stderr)[-2:] == [
        f"gonio scan: warning: the run's end (completed) is not recorded: cannot write "
        f"{run_dir / 'meta.json'}: Operation not permitted; its 4 readings are stored in "
        f"{run_dir / 'readings.jsonl'} (once the directory takes writes, `gonio scan --resume "
        f"{run_dir}` records it)",
        "gonio scan: completed, 4 readings stored"]
    run = open_run(run_dir)
    assert run.meta["status"] == "running" and len(run) == 4  # what the directory let it keep
    resumed = gonio_cli("scan", "--resume", run_dir, "--no-plot", "--no-progress")
    assert resumed.returncode == 0, resumed.stderr
    assert open_run(run_dir).meta["status"] == "completed"
    assert gonio_cli("check", run_dir).returncode == 0


@pytest.mark.parametrize(("ending", "then", "code", "reason"), [
    ([{"do": "SIGTERM", **START_SESSION}], "SIGINT", 128 + signal.SIGTERM, "SIGTERM"),
    ([{"do": "SIGINT", "at": "socket.bind", "match": r"control\.sock$"},
      {"do": "SIGINT", **START_SESSION}], "SIGINT", 130, "aborted by the user (Ctrl-C)"),
    ([{"do": "SIGINT", "at": "socket.bind", "match": r"control\.sock$"},
      {"do": "SIGINT", **START_SESSION}], "SIGTERM", 130, "aborted by the user (Ctrl-C)"),
], ids=["sigterm-then-ctrl-c", "ctrl-c-then-ctrl-c", "ctrl-c-then-sigterm"])
def test_a_signal_after_an_abort_keeps_the_aborts_exit_code(tmp_path, ending, then, code,
                                                             reason):
    """The abort is recorded as the session starts; the next signal comes as the devices are
    closed, after the run has ended."""
    proc = scan_at(tmp_path, [*ending, {"do": then, **CLOSE_DEVICES}])
    assert proc.returncode == code, proc.stderr
    run = open_run(only_run(proc, tmp_path / "runs"))
    assert (run.meta["status"], run.meta["reason"]) == ("aborted", reason)
    assert scan_messages(proc.stderr)[-1] == f"gonio scan: run aborted after 0 readings: {reason}"
