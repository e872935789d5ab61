"""A disk that refuses a write: one clear line, a `failed` status with the reason where the disk
still allows it, no half-made run directory, and a run that resumes once there is room again;
an unwritable --out or export path is one line; a closed pipe ends quietly.
The full disk is a small tmpfs where the test may mount one (as root), and a file-size limit
(RLIMIT_FSIZE: EFBIG, SIGXFSZ being ignored by Python) everywhere."""

import os
import resource
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from gonio_testkit import (
    ROOT,
    fast_config,
    gonio_cli,
    one_line_error,
    run_dir_of,
    scan_messages,
    write_plan,
)

from gonio.store import open_run

PLAN = {"name": "disk", "sample": {"id": "disk-test", "kind": "hemisphere", "eta": 1.51},
        "grid": [{"theta_i_deg": [30.0],
                                  "theta_o_deg": {"start": -80.0, "stop": 80.0, "step": 4.0},
                                  "skip_forbidden": True}]}
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}


def limited_scan(plan: Path, out: Path, max_file_bytes: int) -> subprocess.CompletedProcess:
    """`gonio scan PLAN --sim` with every file it writes limited to max_file_bytes."""
    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (max_file_bytes, max_file_bytes))

    return subprocess.run([sys.executable, "-m", "gonio_cli", "scan", str(plan), "--sim",
                           "--out", str(out), "--no-plot", "--no-progress"],
                          capture_output=True, text=True, cwd=ROOT, env=ENV, timeout=120,
                          preexec_fn=limit)


def refused_then_resumed(proc: subprocess.CompletedProcess, why: str) -> Path:
    """The scan ended on one stderr line naming `why` and printed its run directory; resumed,
    it completes and `gonio check` finds it clean. Returns the run directory."""
    lines = scan_messages(proc.stderr)
    assert proc.returncode == 1 and len(lines) == 1 and why in lines[0], proc.stderr
    assert lines[0].startswith("gonio scan: run failed after ")
    run_dir = run_dir_of(proc)
    assert lines[0].endswith(f"(once that is fixed, `gonio scan --resume {run_dir}` "
                             "continues it)")
    assert [p.name for p in run_dir.parent.iterdir()] == [run_dir.name]  # no .partial left
    resumed = gonio_cli("scan", "--resume", run_dir, "--no-plot")
    assert resumed.returncode == 0, resumed.stderr
    run = open_run(run_dir)
    assert run.meta["status"] == "completed" and len(run) == run.meta["planned"]
    assert gonio_cli("check", run_dir).returncode == 0
    return run_dir


def test_a_file_size_limit_fails_the_run_with_its_reason_and_it_resumes(tmp_path):
    plan = write_plan(tmp_path, PLAN, fast_config())
    proc = limited_scan(plan, tmp_path / "runs", 9_000)  # about half the readings
    meta = open_run(run_dir_of(proc)).meta
    assert meta["status"] == "failed" and "readings.jsonl: File too large" in meta["reason"]
    run_dir = refused_then_resumed(proc, "File too large")
    export = gonio_cli("export", run_dir, "--format", "csv", "--out", tmp_path / "no" / "x.csv")
    assert export.returncode == 2 and "no/x.csv: No such file or directory" in one_line_error(
        export.stderr)


def test_a_run_directory_the_disk_refuses_is_not_left_half_made(tmp_path):
    proc = limited_scan(write_plan(tmp_path, PLAN, fast_config()), tmp_path / "runs", 100)
    assert proc.returncode == 2 and proc.stdout == ""
    assert "cannot make a run directory there" in one_line_error(proc.stderr)
    assert list((tmp_path / "runs").iterdir()) == []


def test_an_unwritable_out_is_one_line(tmp_path):
    proc = gonio_cli("scan", write_plan(tmp_path, PLAN, fast_config()), "--sim", "--out",
                     "/dev/null/x", "--no-plot")
    assert proc.returncode == 2 and one_line_error(proc.stderr).endswith(
        "/dev/null/x: cannot make a run directory there (Not a directory)")


@pytest.fixture
def small_disk(tmp_path):
    """A 1 MiB tmpfs of the test's own (root only)."""
    disk = tmp_path / "disk"
    disk.mkdir()
    if os.geteuid() != 0 or subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs",
                                            str(disk)], capture_output=True).returncode:
        pytest.skip("cannot mount a tmpfs here (the file-size limit tests cover EFBIG)")
    try:
        yield disk
    finally:
        subprocess.run(["umount", "-l", str(disk)], check=True)


def free_bytes(path: Path) -> int:
    st = os.statvfs(path)
    return st.f_bavail * st.f_frsize


def fill(disk: Path, leave: int) -> Path:
    """A filler file taking all of the disk's free space but `leave` bytes."""
    filler = disk / "filler"
    with open(filler, "wb") as fh:
        try:
            while True:
                fh.write(b"\0" * 65536)
                fh.flush()
        except OSError:
            pass
    os.truncate(filler, max(0, filler.stat().st_size - leave))
    return filler


def test_a_full_disk_fails_the_run_and_it_resumes_once_there_is_room(tmp_path, small_disk):
    plan = write_plan(tmp_path, PLAN, fast_config())
    before = free_bytes(small_disk)
    reference = gonio_cli("scan", plan, "--sim", "--out", small_disk / "ref", "--no-plot")
    assert reference.returncode == 0, reference.stderr
    used = before - free_bytes(small_disk)
    readings = (run_dir_of(reference) / "readings.jsonl").stat().st_size
    shutil.rmtree(small_disk / "ref")
    filler = fill(small_disk, used - readings // 2)  # room for about half the readings
    proc = gonio_cli("scan", plan, "--sim", "--out", small_disk / "runs", "--no-plot",
                     "--no-progress")
    meta = open_run(run_dir_of(proc)).meta
    assert meta["status"] == "failed" and "No space left on device" in meta["reason"]
    assert not (run_dir_of(proc) / ".reserve").exists()  # the room kept for meta.json
    filler.unlink()
    refused_then_resumed(proc, "No space left on device")


def test_a_closed_pipe_ends_quietly():
    proc = subprocess.Popen([sys.executable, "-m", "gonio_cli", "plan", "--list",
                             "examples/plans/demo.toml"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, cwd=ROOT, env=ENV)
    proc.stdout.close()  # `| head` that has read all it wanted
    _, err = proc.communicate(timeout=60)
    assert (proc.returncode, err) == (128 + signal.SIGPIPE, b"")
