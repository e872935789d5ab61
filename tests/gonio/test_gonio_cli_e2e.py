"""End to end through the `gonio` CLI in a subprocess: emulators on real ptys and loopback
TCP, real drivers, the engine and the store; in-plane and out-of-plane, ESP, Zaber and Modbus."""

import math

import numpy as np
import pytest
from gonio_testkit import EXAMPLES, fast_config, gonio_cli, one_line_error, run_dir_of, write_plan

from gonio.config import parse_config
from gonio.geometry import stage_angles
from gonio.plan import build_schedule, parse_plan
from gonio.store import open_run

IN_PLANE = {"name": "in-plane", "dark": {"every": 10}, "beam": {"every": 10}, "grid": [
    {"side": "reflection", "theta_i_deg": [0.0, 45.0],
     "theta_o_deg": {"start": -70.0, "stop": 70.0, "step": 20.0}, "skip_forbidden": True},
    {"side": "transmission", "theta_i_deg": [20.0], "theta_o_deg": [-10.0, 0.0, 13.0, 40.0]}]}

OUT_OF_PLANE = {"name": "out-of-plane", "grid": [
    {"side": ["reflection", "transmission"], "theta_i_deg": [30.0],
     "theta_o_deg": [20.0, 40.0], "phi_o_deg": [0.0, 30.0, 60.0, 120.0]}]}


def check_run(run_dir, plan_raw, cfg_raw):
    run = open_run(run_dir)
    assert run.meta["status"] == "completed", run.meta["reason"]
    sched = build_schedule(parse_plan(plan_raw), parse_config(cfg_raw))
    r = run.readings()
    assert list(r["index"]) == list(range(len(sched)))
    np.testing.assert_array_equal(r["kind"], sched.readings["kind"])
    for role in ("sample", "arm", "elevation"):  # stages went where the plan said
        np.testing.assert_allclose(r[f"{role}_deg"], sched.readings[f"{role}_deg"], atol=2e-3)
    s = r[r["kind"] == "sample"]
    # the recorded sample-frame angles are those of the plan's points
    trans = s["side"] == "transmission"
    theta_side = np.where(trans, 180.0 - s["theta_o_deg"], s["theta_o_deg"])
    np.testing.assert_allclose(theta_side, np.abs(s["plan_theta_o_deg"]), atol=2e-3)
    np.testing.assert_allclose(s["theta_i_deg"], np.abs(s["plan_theta_i_deg"]), atol=2e-3)
    assert (s["power_w"] > 0).any() and np.isfinite(r["power_w"]).all()
    beam, dark = r[r["kind"] == "beam"], r[r["kind"] == "dark"]
    if len(beam):
        assert beam["power_w"].min() > 100 * max(dark["power_w"].max(), 1e-12)
    return run


@pytest.mark.parametrize("instrument", ["sim-serial", "sim-zaber", "sim-modbus"])
@pytest.mark.parametrize("plan", [IN_PLANE, OUT_OF_PLANE], ids=["in-plane", "out-of-plane"])
def test_scan_end_to_end(tmp_path, instrument, plan):
    cfg = fast_config(instrument, elevation=plan is OUT_OF_PLANE)
    path = write_plan(tmp_path, plan, cfg)
    proc = gonio_cli("scan", path, "--sim", "--out", path.parent / "runs", "--no-plot")
    assert proc.returncode == 0, proc.stderr
    run = check_run(run_dir_of(proc), plan, cfg)
    if plan is OUT_OF_PLANE:
        s = run.readings()
        s = s[s["kind"] == "sample"]
        expected = stage_angles(s["plan_theta_i_deg"], s["plan_theta_o_deg"],
                                s["plan_phi_o_deg"], s["side"] == "transmission")
        np.testing.assert_allclose(s["elevation_deg"], expected.elevation_deg, atol=2e-3)
        assert np.ptp(s["elevation_deg"]) > 30.0


def test_readme_demo_under_a_minute(tmp_path):
    """The README's first command, as shipped (time scale 50, full aperture integral)."""
    proc = gonio_cli("scan", EXAMPLES / "plans" / "demo.toml", "--sim", "--out", tmp_path,
                     timeout=60.0)
    assert proc.returncode == 0, proc.stderr
    run_dir = run_dir_of(proc)
    assert run_dir.parent == tmp_path
    run = open_run(run_dir)
    assert run.meta["status"] == "completed"
    assert len(run) == run.meta["planned"] == 72
    png = (run_dir / "plot.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10_000
    assert f"completed, 72 readings stored; plot {run_dir / 'plot.png'}" in proc.stderr


def test_export_csv_and_netcdf_round_trip(tmp_path):
    cfg = fast_config()
    path = write_plan(tmp_path, {"grid": [{"theta_i_deg": [10.0], "theta_o_deg": [20.0, 30.0]}],
                      "beam": {"every": 1}}, cfg)
    run_dir = run_dir_of(gonio_cli("scan", path, "--sim", "--out", tmp_path, "--no-plot"))
    r = open_run(run_dir).readings()
    assert gonio_cli("export", run_dir, "--format", "csv", "--out", tmp_path / "r.csv"
                     ).returncode == 0
    import csv
    lines = [ln for ln in (tmp_path / "r.csv").read_text().splitlines() if not ln.startswith("#")]
    rows = list(csv.DictReader(lines))
    assert len(rows) == len(r)
    np.testing.assert_allclose([float(x["power_w"]) for x in rows], r["power_w"], rtol=0)
    assert [x["kind"] for x in rows] == list(r["kind"])
    assert all(math.isnan(v) for v in r["plan_theta_o_deg"][r["kind"] == "beam"])
    proc = gonio_cli("export", run_dir, "--format", "netcdf", "--out", tmp_path / "r.nc")
    assert proc.returncode == 0
    # without dark readings the run cannot be reduced: the default export is its raw readings
    assert "the run cannot be reduced" in proc.stderr and "wrote its raw readings" in proc.stderr
    import netCDF4
    with netCDF4.Dataset(tmp_path / "r.nc") as ds:
        np.testing.assert_array_equal(ds["power_w"][:], r["power_w"])
        np.testing.assert_array_equal(ds["arm_deg"][:], r["arm_deg"])
        kinds = np.array(ds["kind"].flag_meanings.split())[ds["kind"][:]]  # a flag variable
        assert list(kinds) == list(r["kind"])
        assert ds["arm_deg"].units == "degree" and ds.status == "completed"
        # an all-emulated run counts t_s on the bench's virtual clock: run time, not an epoch
        assert ds.Conventions == "CF-1.8" and ds["t_s"].units == "s"
        assert "virtual clock" in ds["t_s"].comment


def test_time_scale_override_and_raw_quick_look(tmp_path):
    """--time-scale replaces a crawling [sim] time scale; a run without dark readings cannot
    be reduced, so its plot.png is the raw quick look; --time-scale needs --sim."""
    cfg = fast_config(time_scale=1.0)  # real time: the moves would take seconds
    plan = {"grid": [{"theta_i_deg": [20.0], "theta_o_deg": [10.0, 30.0, 50.0]}]}
    path = write_plan(tmp_path, plan, cfg)
    proc = gonio_cli("scan", path, "--sim", "--time-scale", "inf", "--out", tmp_path,
                     timeout=60)
    assert proc.returncode == 0, proc.stderr
    run = open_run(run_dir_of(proc))
    assert run.config["sim"]["time_scale"] == "inf" and len(run) == 3
    assert "plot.png shows raw power" in proc.stderr
    assert (run.path / "plot.png").read_bytes()[:4] == b"\x89PNG"
    bad = gonio_cli("scan", path, "--time-scale", "5", "--out", tmp_path)
    assert bad.returncode == 2
    assert one_line_error(bad.stderr).endswith("use it with --sim")
