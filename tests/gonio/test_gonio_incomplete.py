"""Incomplete and failed runs say so. A run stopped short of its plan (aborted at 14 of 24
readings by the stand-in Ctrl-C; a completed run's readings cut) is named by every reader
(reduce, fit, plot, export in every format, watch, calibrate build): one stderr line with
`incomplete`, `N of M readings` and the status, the exit as before, and the same facts in each
output's header, read back with the readers the suite uses (csv, netCDF4, ElementTree, json).
`gonio check` reports completeness beside integrity. A scan whose detector gives no valid
reading fails, naming the detector, as soon as the plan's share of invalid readings is out of
reach, or at its end with the share allowing all. Real emulators on ptys, the real CLI."""

from __future__ import annotations

import json
import shutil
import signal
import tomllib
import urllib.parse
import urllib.request
import xml.etree.ElementTree as ET
from pathlib import Path

import netCDF4
import pytest
from gonio_testkit import (
    EXAMPLES,
    AbortAfter,
    fast_config,
    gonio_cli,
    run_dir_of,
    start_gonio,
    write_plan,
)

from calibration import calfile
from gonio.completeness import Completeness, completeness_of
from gonio.reading_flags import INVALID, flagged
from gonio.runner import new_scan
from gonio.store import META, open_run
from gonio_cli.main import main
from gonio_watch.status import Live, status_of

SAMPLE = tomllib.loads((EXAMPLES / "plans" / "demo.toml").read_text())["sample"]
PLAN = {"name": "short", "dark": {"every": 10}, "beam": {"every": 10}, "grid": [
    {"side": "reflection", "theta_i_deg": [0.0, 30.0],
     "theta_o_deg": {"start": -60.0, "stop": 75.0, "step": 15.0}, "skip_forbidden": True}],
    "sample": SAMPLE}
PLANNED, STOPPED_AT = 24, 14
SAID = f"incomplete run: {STOPPED_AT} of {PLANNED} readings stored, status aborted"
FACTS = {"status": "aborted", "complete": False, "stored_readings": STOPPED_AT,
         "planned_readings": PLANNED}


@pytest.fixture(scope="module")
def aborted(tmp_path_factory) -> Path:
    """An emulated run of PLAN aborted after STOPPED_AT of its PLANNED readings."""
    root = tmp_path_factory.mktemp("short")
    result = new_scan(write_plan(root, PLAN, fast_config()), sim=True, out=root / "runs",
                      progress=False, control=AbortAfter(STOPPED_AT))
    assert result.outcome.status == "aborted" and result.outcome.done == STOPPED_AT
    assert open_run(result.path).meta["planned"] == PLANNED
    return result.path


def warned(err: str, verb: str, run: Path) -> None:
    """stderr holds exactly one line naming the incomplete run, from `verb`."""
    lines = [ln for ln in err.splitlines() if "incomplete run" in ln]
    assert lines == [f"gonio {verb}: warning: {run}: {SAID} (aborted by the user)"], err


def comment_record(path: Path, prefix: str = "# ") -> dict:
    """The `key: JSON` facts of a text file's header comments."""
    out = {}
    for line in path.read_text().splitlines():
        if line.startswith(prefix) and ": " in line:
            key, value = line[len(prefix):].split(": ", 1)
            try:
                out.setdefault(key, json.loads(value))
            except ValueError:
                continue
    return out


def has_facts(record: dict) -> None:
    assert {k: record.get(k) for k in FACTS} == FACTS, record


def test_reduce_fit_and_plot_name_the_incomplete_run(aborted, tmp_path, capsys):
    assert main(["reduce", str(aborted), "--out", str(tmp_path / "r.csv")]) == 0
    warned(capsys.readouterr().err, "reduce", aborted)
    has_facts(comment_record(tmp_path / "r.csv"))

    assert main(["fit", str(aborted), "--distribution", "ggx", "--json"]) == 0
    out = capsys.readouterr()
    warned(out.err, "fit", aborted)
    fitted = json.loads(out.out.strip().splitlines()[-1])
    assert fitted["completeness"] == {**FACTS, "reason": "aborted by the user"}
    assert main(["fit", str(aborted), "--distribution", "ggx"]) == 0
    out = capsys.readouterr()
    warned(out.err, "fit", aborted)
    assert f"  {SAID} (aborted by the user)" in out.out.splitlines()

    assert main(["plot", str(aborted), "--out", str(tmp_path / "p.png")]) == 0
    warned(capsys.readouterr().err, "plot", aborted)
    assert (tmp_path / "p.png").stat().st_size > 0


def test_every_export_format_carries_the_facts(aborted, tmp_path, capsys):
    made = {"csv": ["r.csv"], "netcdf": ["r.nc"], "astm": ["r.astm"], "bluesky": ["r.jsonl"],
            "zemax": ["z.bsdf", "--force", "--distribution", "ggx"],
            "mitsuba": ["m.xml", "--force", "--distribution", "ggx"]}
    for fmt, (name, *options) in made.items():
        assert main(["export", str(aborted), "--format", fmt, "--out", str(tmp_path / name),
                     *options]) == 0, fmt
        warned(capsys.readouterr().err, "export", aborted)
    for name in ("r.csv", "r.astm", "z.bsdf"):
        has_facts(comment_record(tmp_path / name))
    with netCDF4.Dataset(tmp_path / "r.nc") as ds:
        attrs = {key: ds.getncattr(key) for key in ds.ncattrs()}
    has_facts({**attrs, "complete": json.loads(attrs["complete"])})
    tree = ET.parse(tmp_path / "m.xml", ET.XMLParser(target=ET.TreeBuilder(
        insert_comments=True)))
    texts = [c.text.strip() for c in tree.iter() if c.tag is ET.Comment]
    has_facts({k: json.loads(v) for k, v in (t.split(": ", 1) for t in texts if ": " in t
                                             and t.split(": ", 1)[0] in FACTS)})
    documents = [json.loads(line) for line in (tmp_path / "r.jsonl").read_text().splitlines()]
    start, stop = documents[0][1], documents[-1][1]
    has_facts(start["gonio"])
    assert start["num_points"] == PLANNED and stop["exit_status"] == "abort"
    assert stop["num_events"] == {"primary": STOPPED_AT}


def test_bad_arguments_give_their_error_alone_without_the_incomplete_warning(aborted,
                                                                             tmp_path, capsys):
    assert main(["export", str(aborted), "--format", "csv", "--out", str(tmp_path / "x")]) == 2
    assert capsys.readouterr().err.splitlines() == [
        f"gonio export: error: export: --out {tmp_path / 'x'} has no suffix; --format csv "
        "writes .csv"]
    assert main(["reduce", str(aborted), "--coverage-k", "0"]) == 2
    assert capsys.readouterr().err.splitlines() == [
        "gonio reduce: error: --coverage-k must be a finite number > 0, got 0.0"]
    assert not (tmp_path / "x").exists()


def test_check_reports_completeness_and_exits_0_for_an_intact_incomplete_run(aborted, tmp_path):
    proc = gonio_cli("check", aborted)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    assert f"  {SAID} (aborted by the user)" in lines
    assert lines[-1] == f"intact but incomplete: {STOPPED_AT} of {PLANNED} readings stored, " \
                        "status aborted"
    # a completed run whose readings were cut: fewer than planned, and its sessions disagree
    cut = Path(shutil.copytree(aborted, tmp_path / "cut"))
    meta = json.loads((cut / META).read_text())
    (cut / META).write_text(json.dumps({**meta, "status": "completed", "sessions": []}))
    assert not completeness_of(open_run(cut)).complete
    proc = gonio_cli("check", cut)
    assert proc.returncode == 1 and proc.stdout.splitlines()[-1] == "damaged"
    assert f"incomplete run: {STOPPED_AT} of {PLANNED} readings stored, status completed" \
        in proc.stdout


def test_an_older_run_without_a_planned_count_takes_it_from_its_plan(aborted, tmp_path):
    old = Path(shutil.copytree(aborted, tmp_path / "old"))
    meta = json.loads((old / META).read_text())
    del meta["planned"]
    (old / META).write_text(json.dumps(meta))
    found = completeness_of(open_run(old))
    assert (found.stored, found.planned, found.complete) == (STOPPED_AT, PLANNED, False)


def test_watch_names_an_ended_incomplete_run_on_stderr_and_its_page(aborted):
    proc = start_gonio("watch", aborted)
    try:
        page = urllib.parse.urlsplit(proc.stdout.readline().strip())  # http://...:P/?key=SECRET
        status_url = page._replace(path="/status.json").geturl()
        with urllib.request.urlopen(status_url, timeout=30) as reply:
            status = json.load(reply)
    finally:
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=30)
    assert proc.returncode == 0
    warned(err, "watch", aborted)
    assert status["incomplete"] == f"{SAID} (aborted by the user)"


def test_the_watch_status_names_no_run_in_progress_and_no_complete_run(aborted):
    run = open_run(aborted)
    meta = {"status": "running", "reason": "", "planned": 3, "sessions": []}
    rows = [{"index": 0, "t_s": 0.0}]
    assert status_of(run, meta, rows, Live(True), 0.0)["incomplete"] is None
    done = {**meta, "status": "completed"}
    assert status_of(run, done, rows * 3, Live(False), 0.0)["incomplete"] is None
    assert status_of(run, done, rows, Live(False), 0.0)["incomplete"] == \
        "incomplete run: 1 of 3 readings stored, status completed"


def test_the_watch_status_of_an_older_run_takes_its_planned_count_from_its_plan(aborted,
                                                                                tmp_path):
    old = Path(shutil.copytree(aborted, tmp_path / "old"))
    meta = json.loads((old / META).read_text())
    del meta["planned"]
    (old / META).write_text(json.dumps(meta))
    run = open_run(old)
    out = status_of(run, run.meta, run.rows(), Live(False), 0.0)
    assert out["planned"] == PLANNED and out["incomplete"] == f"{SAID} (aborted by the user)"


def aborted_calibration(tmp_path: Path, plan_name: str, stop_at: int, **changes) -> tuple:
    """(run, what an incomplete-run line says of it): a shipped calibration plan on the fast
    bench, aborted after stop_at readings."""
    plan = tomllib.loads((EXAMPLES / "plans" / f"{plan_name}.toml").read_text())
    plan.pop("instrument")
    plan.update(changes)
    result = new_scan(write_plan(tmp_path, plan, fast_config(), name=plan_name), sim=True,
                      out=tmp_path / "runs", progress=False, control=AbortAfter(stop_at))
    planned = open_run(result.path).meta["planned"]
    return result.path, (f"incomplete run: {stop_at} of {planned} readings stored, status "
                         "aborted (aborted by the user)")


def test_calibrate_build_names_an_incomplete_run_and_records_it(tmp_path):
    run, said = aborted_calibration(tmp_path, "calib-detector", 190, repeats=1)
    proc = gonio_cli("calibrate", "build", run, "--out", tmp_path / "cal.json")
    assert [ln for ln in proc.stderr.splitlines() if "incomplete run" in ln] == [
        f"gonio calibrate: warning: {run}: {said}"], proc.stderr
    assert proc.returncode == 0, proc.stderr
    assert f"{run}: {said}" in calfile.load(tmp_path / "cal.json").notes


def test_calibrate_build_names_an_incomplete_aperture_scan_too(tmp_path):
    run, said = aborted_calibration(tmp_path, "calib-detector", 190, repeats=1)
    scan, scan_said = aborted_calibration(tmp_path, "calib-aperture", 95)
    proc = gonio_cli("calibrate", "build", run, "--aperture-scan", scan, "--out",
                     tmp_path / "cal.json")
    assert [ln for ln in proc.stderr.splitlines() if "incomplete run" in ln] == [
        f"gonio calibrate: warning: {run}: {said}",
        f"gonio calibrate: warning: {scan}: {scan_said}"], proc.stderr
    assert proc.returncode == 0, proc.stderr
    notes = calfile.load(tmp_path / "cal.json").notes
    assert f"{run}: {said}" in notes and f"{scan}: {scan_said}" in notes


DEAD = {"name": "dead", "grid": [
    {"side": "reflection", "theta_i_deg": [30.0],
     "theta_o_deg": {"start": -60.0, "stop": 75.0, "step": 5.0}, "skip_forbidden": True}]}


@pytest.mark.parametrize("share, stored", [(None, 3), (1.0, 25)])
def test_a_detector_without_one_valid_reading_fails_the_scan(tmp_path, share, stored):
    """Every reading invalid (the PM100 answers SCPI's not-a-number each time): with the
    default share (0.1 of 25 readings: 2 allowed) the run stops at the third, with every
    reading allowed invalid it measures all and fails at the end; either way failed, the
    detector named, exit 1."""
    plan = dict(DEAD, **({} if share is None else {"max_invalid_share": share}))
    path = write_plan(tmp_path, plan, fast_config(faults={"pm100": {"invalid_prob": 1.0}}))
    proc = gonio_cli("scan", path, "--sim", "--out", tmp_path / "runs", "--no-plot",
                     "--no-progress")
    assert proc.returncode == 1, proc.stderr
    run = open_run(run_dir_of(proc))
    assert run.status == "failed" and run.meta["planned"] == 25
    assert run.meta["reason"].startswith(f"detector 'pm100' gave no valid reading: {stored} of "
                                         f"{stored} readings stored are invalid")
    assert flagged(run.readings(), INVALID).all() and len(run.readings()) == stored
    assert f"gonio scan: run failed after {stored} readings: detector 'pm100' gave no valid " \
           "reading" in proc.stderr
    assert "start a new scan" in proc.stderr and "--resume" not in proc.stderr
    again = gonio_cli("scan", "--resume", run.path, "--sim", "--no-plot", "--no-progress")
    assert again.returncode == (2 if share is None else 1), again.stderr  # refused | failed
    assert "start a new scan" in again.stderr, again.stderr
    resumed = open_run(run.path)  # refused, or failed again: nothing measured, never completed
    assert resumed.status == "failed" and len(resumed.readings()) == stored
    assert Completeness.from_json(completeness_of(run).to_json()).text().startswith(
        f"incomplete run: {stored} of 25 readings stored, status failed")
