"""Damage in a run, through the real CLI: a damaged line in the middle of readings.jsonl is
reported by every reader (export refuses rather than writing part of the run), resume refuses,
`gonio check` says so (exit 1) and `--repair` writes a copy that keeps every valid reading and
resumes by measuring exactly the dropped ones; a torn or NUL-padded tail is still cut and
resumed. Resume refuses an edited plan.json and a config that differs in more than device
endpoints, and records an endpoint change."""

import json
import shutil

import numpy as np
import pytest
from gonio_testkit import (
    AbortAfter,
    fast_config,
    gonio_cli,
    one_line_error,
    run_dir_of,
    write_plan,
    write_toml,
)

from gonio.runner import new_scan
from gonio.store import open_run

PLAN = {"name": "check", "dark": {"every": 10}, "beam": {"every": 30}, "grid": [
    {"side": "reflection", "theta_i_deg": [20.0],
     "theta_o_deg": {"start": -60.0, "stop": 75.0, "step": 5.0}, "skip_forbidden": True}]}
SAME_POSITION = ("index", "kind", "side", "repeat", "point", "sample_deg", "arm_deg",
                 "plan_theta_o_deg")


@pytest.fixture(scope="module")
def completed(tmp_path_factory):
    """A completed emulated run of PLAN (31 readings): (folder, run directory, readings)."""
    root = tmp_path_factory.mktemp("check")
    plan = write_plan(root, PLAN, fast_config())
    proc = gonio_cli("scan", plan, "--sim", "--out", root / "runs", "--no-plot",
                     "--no-progress")
    assert proc.returncode == 0, proc.stderr
    run_dir = run_dir_of(proc)
    return root, run_dir, open_run(run_dir).readings()


def damaged_copy(run_dir, tmp_path, line_10: bytes | None):
    """A copy of the run with its line 10 replaced (None: by a copy of line 9)."""
    copy = shutil.copytree(run_dir, tmp_path / "damaged")
    path = copy / "readings.jsonl"
    lines = path.read_bytes().splitlines(keepends=True)
    lines[9:10] = [lines[8]] if line_10 is None else [line_10]
    path.write_bytes(b"".join(lines))
    return copy


DAMAGE = {"garbage": (b'{"index": 9, "kind": "sa}}\n', "line 10: not JSON"),
          "nul": (b"\x00" * 200 + b"\n", "line 10: NUL bytes"),
          "duplicated": (None, "line 10: duplicate of index 8 (line 9)")}


@pytest.mark.parametrize("kind", DAMAGE)
def test_a_damaged_line_is_reported_refused_and_repaired(completed, tmp_path, kind):
    _, run_dir, ref = completed
    line_10, said = DAMAGE[kind]
    run = damaged_copy(run_dir, tmp_path, line_10)
    if kind == "garbage":  # every reader of the store, through the CLI
        out = tmp_path / "part.csv"
        for args in (("export", run, "--format", "csv", "--out", out), ("reduce", run),
                     ("fit", run)):
            proc = gonio_cli(*args)
            assert proc.returncode == 2, proc.stderr
            assert f"readings.jsonl {said}" in one_line_error(proc.stderr)
        assert not out.exists()  # no file of the first 9 rows
    before = (run / "readings.jsonl").read_bytes()
    proc = gonio_cli("scan", "--resume", run, "--no-plot")
    assert proc.returncode == 2
    assert f"{said}; cannot resume: `gonio check {run} --repair OUT_DIR`" in one_line_error(
        proc.stderr)
    assert (run / "readings.jsonl").read_bytes() == before

    fixed = tmp_path / "fixed"
    proc = gonio_cli("check", run, "--repair", fixed)
    assert proc.returncode == 1, proc.stderr
    assert f"readings.jsonl {said}" in proc.stdout and run_dir_of(proc) == fixed
    copy = open_run(fixed)
    dropped = [9]
    assert copy.meta["repair"]["dropped"] == dropped
    assert copy.rows() == [r for r in open_run(run_dir).rows() if r["index"] not in dropped]
    assert gonio_cli("check", fixed).returncode == 0
    if kind == "garbage":
        proc = gonio_cli("check", run, "--repair", fixed)
        assert proc.returncode == 2 and "already exists" in one_line_error(proc.stderr)
    if kind != "nul":
        return  # the copies are alike: resume one of them

    proc = gonio_cli("scan", "--resume", fixed, "--no-plot", "--no-progress")
    assert proc.returncode == 0, proc.stderr
    done = open_run(fixed)
    assert done.status == "completed"
    got = done.readings()
    for field in SAME_POSITION:
        np.testing.assert_array_equal(got[field], ref[field], err_msg=field)
    assert done.meta["sessions"][-1]["refill"] == dropped


@pytest.fixture
def aborted(tmp_path):
    """An emulated run of PLAN aborted after 12 readings: (plan file, run directory)."""
    plan = write_plan(tmp_path, PLAN, fast_config())
    result = new_scan(plan, sim=True, out=tmp_path / "runs", progress=False,
                      control=AbortAfter(12))
    assert result.outcome.status == "aborted" and result.outcome.done == 12
    return plan, result.path


def test_a_torn_nul_padded_tail_is_cut_and_resumed(completed, aborted):
    ref = completed[2]
    _, run = aborted
    with open(run / "readings.jsonl", "ab") as fh:
        fh.write(b'{"index": 12, "kind": "sam' + b"\x00" * 500)
    proc = gonio_cli("check", run)
    assert proc.returncode == 0 and "torn last line (526 bytes" in proc.stdout, proc.stdout
    proc = gonio_cli("scan", "--resume", run, "--no-plot", "--no-progress")
    assert proc.returncode == 0, proc.stderr
    got = open_run(run).readings()
    for field in SAME_POSITION:
        np.testing.assert_array_equal(got[field], ref[field], err_msg=field)
    assert b"\x00" not in (run / "readings.jsonl").read_bytes()


def test_an_edited_plan_json_is_refused(aborted):
    _, run = aborted
    plan = json.loads((run / "plan.json").read_text())
    (run / "plan.json").write_text(json.dumps({**plan, "averaging": 8}))
    proc = gonio_cli("scan", "--resume", run, "--no-plot")
    assert proc.returncode == 2
    assert "plan.json changed since the run started" in one_line_error(proc.stderr)
    proc = gonio_cli("check", run)
    assert proc.returncode == 1 and "plan.json changed" in proc.stdout


def test_resume_takes_new_endpoints_only(aborted, tmp_path):
    plan, run = aborted
    cfg = fast_config()
    changed = write_toml(tmp_path / "changed.toml", {
        **cfg, "optics": {**cfg["optics"], "wavelength_nm": 532.0},
        "detector": {**cfg["detector"], "averaging": 1}})
    proc = gonio_cli("scan", "--resume", run, "--instrument", changed, "--no-plot")
    assert proc.returncode == 2
    assert (f"differs from the config {run} was started with in detector.averaging, "
            "optics.wavelength_nm; on resume only device endpoints"
            in one_line_error(proc.stderr))
    other_sample = write_toml(tmp_path / "other.toml", {
        **PLAN, "instrument": plan.with_name("plan-instrument.toml").name,
        "sample": {"id": "another", "kind": "hemisphere", "eta": 1.51}})
    proc = gonio_cli("scan", other_sample, "--resume", run, "--no-plot")
    assert proc.returncode == 2 and "(differs in sample.eta, sample.id, sample.kind)" in \
        one_line_error(proc.stderr)
    assert len(open_run(run)) == 12 and len(open_run(run).meta["sessions"]) == 1
    moved = write_toml(tmp_path / "moved.toml", {**cfg, "devices": {
        **cfg["devices"], "pm100": {**cfg["devices"]["pm100"], "port": "/dev/ttyUSB7"}}})
    proc = gonio_cli("scan", "--resume", run, "--instrument", moved, "--no-plot",
                     "--no-progress")
    assert proc.returncode == 0, proc.stderr
    session = open_run(run).meta["sessions"][-1]
    assert session["endpoint_changes"] == {
        "devices.pm100.port": {"from": "/dev/ttyUSB1", "to": "/dev/ttyUSB7"}}
