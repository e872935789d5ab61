"""Every reader of a run applies the rules `gonio check` applies, with the attack's own
reproductions on a completed emulated run of 72 readings: cut to 67 lines, it is refused by
export, reduce, fit, plot and watch (exit 2, one line), read with --force (every output's
header names what was skipped) and finished by `gonio scan --resume` measuring exactly the 5
lost; readings copied from another run of the same plan fail; an edited config.json and a
deleted line_checksum are damage; --repair keeps a valid line out of order; a run whose
meta.json is lost is rebuilt by --repair and then reads. Real emulators, the real CLI."""

from __future__ import annotations

import json
import shutil
import tomllib
from pathlib import Path

import numpy as np
import pytest
from gonio_testkit import EXAMPLES, fast_config, gonio_cli, one_line_error, run_dir_of, write_plan

from calibration.pipeline import reduce_run
from calibration.plot import plot_title
from gonio.runner import new_scan
from gonio.store import META, READINGS, open_run
from gonio_cli.main import main

PLAN = {"name": "rules", "dark": {"every": 10}, "beam": {"every": 10}, "grid": [
    {"side": "reflection", "theta_i_deg": [0.0, 30.0],
     "theta_o_deg": {"start": -60.0, "stop": 75.0, "step": 4.5}, "skip_forbidden": True}],
    "sample": tomllib.loads((EXAMPLES / "plans" / "demo.toml").read_text())["sample"]}
PLANNED, KEPT = 72, 67
LOST = "indices 67-71 lost"
SAME_POSITION = ("index", "kind", "side", "repeat", "point", "sample_deg", "arm_deg",
                 "plan_theta_o_deg")


def scan(root: Path) -> Path:
    """A completed emulated run of PLAN."""
    result = new_scan(write_plan(root, PLAN, fast_config()), sim=True, out=root / "runs",
                      progress=False)
    assert result.outcome.status == "completed", result.outcome.reason
    assert len(open_run(result.path)) == PLANNED
    return result.path


@pytest.fixture(scope="module")
def completed(tmp_path_factory) -> Path:
    return scan(tmp_path_factory.mktemp("rules"))


def copy_of(run: Path, tmp_path: Path, name: str = "copy") -> Path:
    return Path(shutil.copytree(run, tmp_path / name))


def cut(run: Path, tmp_path: Path) -> Path:
    """A copy of the run with its readings cut to their first KEPT lines."""
    copy = copy_of(run, tmp_path, "cut")
    lines = (copy / READINGS).read_bytes().splitlines(keepends=True)
    (copy / READINGS).write_bytes(b"".join(lines[:KEPT]))
    return copy


def refused(capsys, *argv) -> str:
    """The one error line of a reader that refused (exit 2)."""
    assert main([str(a) for a in argv]) == 2
    return one_line_error(capsys.readouterr().err)


def header(path: Path) -> dict:
    """The `# key: JSON` facts of a text file's header."""
    out = {}
    for line in path.read_text().splitlines():
        if line.startswith("# ") and ": " in line:
            key, value = line[2:].split(": ", 1)
            try:
                out.setdefault(key, json.loads(value))
            except ValueError:
                continue
    return out


def test_a_cut_run_is_refused_by_every_reader_and_read_with_force(completed, tmp_path,
                                                                  capsys):
    run = cut(completed, tmp_path)
    out = tmp_path / "r.csv"
    for argv in (("export", run, "--format", "csv", "--out", out), ("reduce", run),
                 ("fit", run, "--distribution", "ggx"), ("plot", run), ("watch", run)):
        said = refused(capsys, *argv)
        assert f"readings.jsonl ends at index 66, but meta.json records readings up to index " \
               f"71: {LOST}" in said, said
    assert not out.exists() and not (run / "reduced.csv").exists()
    proc = gonio_cli("check", run)
    assert proc.returncode == 1 and proc.stdout.splitlines()[-1] == "damaged"
    assert LOST in proc.stdout

    assert main(["export", str(run), "--format", "csv", "--out", str(out), "--force"]) == 0
    warning = [ln for ln in capsys.readouterr().err.splitlines() if "warning" in ln]
    assert len(warning) == 1 and f"{KEPT} of {PLANNED} readings stored" in warning[0] \
        and LOST in warning[0]
    facts = header(out)
    assert facts["complete"] is False and facts["stored_readings"] == KEPT
    assert any(LOST in d for d in facts["damage"]), facts
    assert main(["reduce", str(run), "--force"]) == 0
    assert any(LOST in d for d in header(run / "reduced.csv")["damage"])
    capsys.readouterr()
    assert main(["fit", str(run), "--force", "--distribution", "ggx", "--json"]) == 0
    fitted = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert any(LOST in d for d in fitted["completeness"]["damage"])
    assert main(["plot", str(run), "--force", "--out", str(tmp_path / "p.png")]) == 0
    assert (tmp_path / "p.png").stat().st_size > 0
    data = reduce_run(open_run(run, force=True))
    assert LOST in plot_title(run.name, data.meta)


def test_resume_measures_exactly_the_lost_readings(completed, tmp_path):
    ref = open_run(completed).readings()
    run = cut(completed, tmp_path)
    proc = gonio_cli("scan", "--resume", run, "--no-plot", "--no-progress")
    assert proc.returncode == 0, proc.stderr
    done = open_run(run)
    assert done.status == "completed" and done.meta["stored"] == PLANNED
    session = done.meta["sessions"][-1]
    assert (session["first_index"], session["refill"]) == (KEPT, list(range(KEPT, PLANNED)))
    got = done.readings()
    for field in SAME_POSITION:
        np.testing.assert_array_equal(got[field], ref[field], err_msg=field)
    assert (run / READINGS).read_bytes()[:1000] == (completed / READINGS).read_bytes()[:1000]
    proc = gonio_cli("check", run)
    assert proc.returncode == 0 and proc.stdout.splitlines()[-1] == "clean", proc.stdout

    again = cut(completed, tmp_path / "again")  # or through a repaired copy
    fixed = tmp_path / "fixed"
    proc = gonio_cli("check", again, "--repair", fixed)
    assert proc.returncode == 1 and run_dir_of(proc) == fixed, proc.stdout
    assert open_run(fixed).meta["repair"]["dropped"] == list(range(KEPT, PLANNED))
    proc = gonio_cli("scan", "--resume", fixed, "--no-plot", "--no-progress")
    assert proc.returncode == 0, proc.stderr
    assert open_run(fixed).status == "completed" and len(open_run(fixed)) == PLANNED
    assert gonio_cli("check", fixed).returncode == 0


def test_readings_copied_from_another_run_fail(completed, tmp_path, capsys):
    other = scan(tmp_path)  # the same plan, run again
    shutil.copyfile(completed / READINGS, other / READINGS)
    uid, theirs = open_run(other).meta["run_uid"], open_run(completed).meta["run_uid"]
    said = f"line 1: a line of run {theirs}, not of this run (run_uid {uid}) (index 0)"
    proc = gonio_cli("check", other)
    assert proc.returncode == 1 and said in proc.stdout, proc.stdout
    for argv in (("export", other, "--format", "csv", "--out", tmp_path / "x.csv"),
                 ("reduce", other), ("plot", other)):
        assert said in refused(capsys, *argv)


def test_an_edited_config_json_is_refused(completed, tmp_path, capsys):
    run = copy_of(completed, tmp_path)
    config = json.loads((run / "config.json").read_text())
    config["optics"]["wavelength_nm"] += 100.0
    (run / "config.json").write_text(json.dumps(config))
    out = tmp_path / "r.csv"
    said = "config.json changed since the run started (its digest differs)"
    assert said in refused(capsys, "export", run, "--format", "csv", "--out", out)
    assert not out.exists()
    assert main(["export", str(run), "--format", "csv", "--out", str(out), "--force"]) == 0
    assert header(out)["damage"] == [said]


def test_deleting_line_checksum_is_damage(completed, tmp_path, capsys):
    run = copy_of(completed, tmp_path)
    meta = json.loads((run / META).read_text())
    del meta["line_checksum"]
    (run / META).write_text(json.dumps(meta))
    said = "meta.json names no line_checksum: the lines cannot be checked"
    proc = gonio_cli("check", run)
    assert proc.returncode == 1 and said in proc.stdout
    assert said in refused(capsys, "export", run, "--format", "csv", "--out", tmp_path / "x.csv")


def test_repair_keeps_a_valid_line_out_of_order(completed, tmp_path):
    run = copy_of(completed, tmp_path)
    lines = (run / READINGS).read_bytes().splitlines(keepends=True)
    lines[10], lines[11] = lines[11], lines[10]
    (run / READINGS).write_bytes(b"".join(lines))
    fixed = tmp_path / "fixed"
    proc = gonio_cli("check", run, "--repair", fixed)
    assert proc.returncode == 1 and "line 12: index 10 out of order" in proc.stdout
    copy = open_run(fixed)
    assert copy.meta["repair"]["dropped"] == [] and copy.status == "completed"
    assert copy.rows() == open_run(completed).rows()
    proc = gonio_cli("check", fixed)
    assert proc.returncode == 0 and proc.stdout.splitlines()[-1] == "clean", proc.stdout


def test_a_lost_meta_json_is_rebuilt_and_the_run_then_reads(completed, tmp_path, capsys):
    run = copy_of(completed, tmp_path)
    (run / META).unlink()
    said = refused(capsys, "export", run, "--format", "csv", "--out", tmp_path / "x.csv")
    assert f"meta.json is missing; `gonio check {run} --repair OUT_DIR` rebuilds it" in said
    assert gonio_cli("check", run).returncode == 1
    fixed = tmp_path / "fixed"
    proc = gonio_cli("check", run, "--repair", fixed)
    assert proc.returncode == 1 and run_dir_of(proc) == fixed, proc.stdout
    rebuilt = open_run(fixed)
    original = open_run(completed)
    assert rebuilt.meta["run_uid"] == original.meta["run_uid"]
    assert (rebuilt.status, rebuilt.meta["planned"]) == ("completed", PLANNED)
    assert rebuilt.rows() == original.rows()
    proc = gonio_cli("check", fixed)
    assert proc.returncode == 0 and proc.stdout.splitlines()[-1] == "clean", proc.stdout
    out = tmp_path / "r.csv"
    assert main(["export", str(fixed), "--format", "csv", "--out", str(out)]) == 0
    assert header(out)["stored_readings"] == PLANNED
