"""An emulated scan builds the multiple-scattering tables its plan needs before the first move,
never inside the meter's reply: on a cold cache with a progress line and none on a warm one,
no plane built while the readings are taken (the session's ms_tables record), the plan's
estimate naming the planes it walks, a cold run killed and resumed on another cold cache
bit for bit the uninterrupted run, and tables altered on disk walked again (one warning).
Real ptys, `gonio scan --sim --time-scale inf`, tables of few walks in a cache directory of
the test's own."""

import numpy as np
from gonio_testkit import (
    completed_unretried,
    fast_config,
    gonio_cli,
    run_dir_of,
    start_gonio,
    wait_for_lines,
    write_plan,
)

from gonio.store import open_run

WALKS = 1024  # cheap tables
PLAN = {"name": "tables", "dark": {"every": 12}, "beam": {"every": 12}, "grid": [
    {"side": ["reflection", "transmission"], "theta_i_deg": [0.0, 35.0],
     "theta_o_deg": {"start": -60.0, "stop": 60.0, "step": 15.0}, "skip_forbidden": True}]}
BAR = "multiple-scattering tables"


def plan_file(tmp_path, alpha: float):
    """The plan on the fast serial bench with a ground glass of roughness alpha (multiple
    scattering on, tables of WALKS walks) and the real aperture rule."""
    cfg = fast_config(pm100={"timeout_s": 10.0})
    del cfg["sim"]["aperture"]["order"]  # the aperture rule's nodes: several planes a reading
    cfg["sim"]["sample"] = {"kind": "hemisphere", "eta": 1.51, "distribution": "ggx",
                            "alpha": alpha, "ms_walks": WALKS, "multiple_scattering": True}
    return write_plan(tmp_path, PLAN, cfg)


def scan(plan, runs):
    return gonio_cli("scan", plan, "--sim", "--time-scale", "inf", "--out", runs, timeout=600)


def tables_of(run) -> dict:
    """The ms_tables record of a run's last session."""
    return run.meta["sessions"][-1]["ms_tables"]


def test_a_cold_scan_walks_its_tables_first_as_estimated_and_a_warm_one_none(tmp_path,
                                                                            monkeypatch):
    monkeypatch.setenv("GONIO_CACHE_DIR", str(tmp_path / "cache"))
    plan = plan_file(tmp_path, 0.3311)
    estimate = gonio_cli("plan", plan, "--sim")
    assert estimate.returncode == 0, estimate.stderr
    cold = scan(plan, tmp_path / "runs")
    tables = tables_of(completed_unretried(cold))
    assert tables["walked"] == tables["planes"] > 1 and tables["read"] == 0
    assert tables["walks"] == WALKS
    assert tables["in_readings"] == 0  # every reading's planes were built before it
    assert f"{BAR}: {tables['walked']} planes to walk before the first move ({WALKS} walks " \
        in estimate.stdout
    assert BAR in cold.stderr and f"{tables['walked']}/{tables['walked']}" in cold.stderr
    warm = scan(plan, tmp_path / "runs")
    again = tables_of(completed_unretried(warm))
    assert again["read"] == again["planes"] == tables["planes"] and again["walked"] == 0
    assert again["in_readings"] == 0
    assert BAR not in warm.stderr
    warm_estimate = gonio_cli("plan", plan, "--sim").stdout
    assert f"{BAR}: none to walk" in warm_estimate
    # preparation still evaluates every reading once (ms_tables seconds of a warm scan)
    assert "; evaluating every reading once before the first move about " in warm_estimate


def test_a_cold_run_killed_and_resumed_cold_is_the_uninterrupted_run_bit_for_bit(tmp_path,
                                                                                monkeypatch):
    plan = plan_file(tmp_path, 0.3313)
    monkeypatch.setenv("GONIO_CACHE_DIR", str(tmp_path / "cache-whole"))
    whole = completed_unretried(scan(plan, tmp_path / "whole"))
    monkeypatch.setenv("GONIO_CACHE_DIR", str(tmp_path / "cache-first"))
    runs = tmp_path / "parts"
    proc = start_gonio("scan", plan, "--sim", "--time-scale", "inf", "--out", runs)
    try:
        wait_for_lines(runs, 9, proc, timeout=300)
    finally:
        proc.kill()
        proc.communicate()
    run_dir = next(runs.iterdir())
    killed = open_run(run_dir).meta["sessions"][0]["ms_tables"]  # recorded before any move
    assert killed["walked"] == killed["planes"] > 0 and killed["in_readings"] == 0
    stored = open_run(run_dir).lines().rows
    assert 9 <= len(stored) < whole.meta["planned"]
    monkeypatch.setenv("GONIO_CACHE_DIR", str(tmp_path / "cache-second"))  # cold again
    resumed = gonio_cli("scan", "--resume", run_dir, timeout=600)
    assert run_dir_of(resumed) == run_dir
    run = completed_unretried(resumed)
    second = tables_of(run)
    assert second["walked"] > 0 and second["in_readings"] == 0
    a, b = whole.readings(), run.readings()
    for name in ("index", "kind", "sample_deg", "arm_deg", "power_w", "range_w", "flags"):
        assert np.array_equal(a[name], b[name]), name


def test_the_bar_counts_the_walks_of_the_cabinet_sample_the_plan_mounts(tmp_path, monkeypatch):
    monkeypatch.setenv("GONIO_CACHE_DIR", str(tmp_path / "cache"))
    cfg = fast_config(pm100={"timeout_s": 10.0})
    cfg["sim"]["sample"] = {"ms_walks": 4 * WALKS}  # not the mounted one
    cfg["sim"]["samples"] = {"cabinet-glass": {
        "distribution": "ggx", "alpha": 0.3317, "ms_walks": WALKS, "multiple_scattering": True}}
    plan = write_plan(tmp_path, {
        "name": "cabinet", "sample": {"id": "cabinet-glass", "kind": "hemisphere", "eta": 1.51},
        "grid": [{"theta_i_deg": [35.0], "theta_o_deg": [-50.0, 30.0]}]}, cfg)
    proc = scan(plan, tmp_path / "runs")
    assert tables_of(completed_unretried(proc))["walks"] == WALKS
    assert f"{BAR} ({WALKS} walks a plane)" in proc.stderr


def test_a_sim_sample_that_is_no_table_is_one_error_line_and_no_run(tmp_path):
    cfg = fast_config()
    cfg["sim"]["sample"] = 3
    proc = scan(write_plan(tmp_path, PLAN, cfg), tmp_path / "runs")
    assert proc.returncode != 0 and "Traceback" not in proc.stderr
    assert [line for line in proc.stderr.splitlines() if line.strip()] == [
        line for line in proc.stderr.splitlines() if "[sim.sample]: must be a table, got 3" in line]
    assert not any((tmp_path / "runs").glob("*"))


def test_tables_altered_on_disk_are_walked_again_and_the_readings_are_the_clean_ones(
        tmp_path, monkeypatch):
    """The attack: every table file's values times 100 (its digest kept) between two scans.
    The second scan says so in one warning line, walks the planes again and measures what
    the first one did."""
    monkeypatch.setenv("GONIO_CACHE_DIR", str(tmp_path / "cache"))
    plan = plan_file(tmp_path, 0.3319)
    clean = completed_unretried(scan(plan, tmp_path / "clean"))
    files = sorted((tmp_path / "cache" / "ms-planes").glob("*.npz"))
    assert len(files) == tables_of(clean)["planes"] > 1
    for path in files:
        with np.load(path) as archive:
            plane, digest = archive["plane"], archive["digest"]
        with path.open("wb") as handle:
            np.savez(handle, plane=100.0 * plane, digest=digest)
    proc = scan(plan, tmp_path / "altered")
    run = completed_unretried(proc)
    warned = [line for line in proc.stderr.splitlines() if "cache" in line]
    assert len(warned) == 1 and warned[0].startswith("gonio: warning: gonio's table cache in ")
    assert "does not match its digest" in warned[0]
    assert tables_of(run)["walked"] == tables_of(run)["planes"] == len(files)
    a, b = clean.readings(), run.readings()
    for name in ("index", "kind", "sample_deg", "arm_deg", "power_w", "range_w", "flags"):
        assert np.array_equal(a[name], b[name]), name
