"""Calibration that fits the plan, as a user meets it: `gonio scan --calibration` refuses a
calibration lacking a range the plan can read on (one line naming the ranges, before the run
directory exists and before any motion); one built from the shipped calib-detector plan covers
the shipped sample plans; `gonio calibrate build` says what it could not calibrate and fails on
what it was asked for but could not do. Real emulators on ptys, the real CLI."""

import json

import pytest
from gonio_testkit import EXAMPLES, gonio_cli, load_example, one_line_error, run_dir_of, write_toml

from calibration import calfile
from calibration.coverage import ranges_read, uncovered
from gonio.config import load_config
from gonio.plan import build_schedule, load_plan, parse_plan
from sim.devices.photodiode import DEFAULT_RANGES_W

PLANS = EXAMPLES / "plans"
ALL_RANGES = ["1e-08", "1e-07", "1e-06", "1e-05", "0.0001", "0.001", "0.01"]
# sim-serial's bench as the experimenter knows it
OPTICS = {"wavelength_nm": 632.8, "bandwidth_nm": 0.002, "beam_diameter_mm": 2.0,
          "divergence_deg": 0.03, "aperture_diameter_mm": 10.0, "aperture_distance_mm": 500.0,
          "source_polarisation": "unpolarised", "analyser_polarisation": "unpolarised"}
QUIET = ("--sim", "--time-scale", "inf", "--no-plot", "--no-progress")


def sim_serial(tmp_path):
    """sim-serial with its [optics], in tmp_path."""
    return write_toml(tmp_path / "sim-serial.toml", {**load_example("sim-serial"),
                                                     "optics": OPTICS})


@pytest.mark.slow
def test_a_calibration_from_the_calib_plan_covers_the_shipped_plans(tmp_path):
    # one run of the shipped calib-detector plan (one test, not a fixture: xdist would run a
    # module fixture once per worker)
    cfg = sim_serial(tmp_path)
    scan = gonio_cli("scan", PLANS / "calib-detector.toml", "--instrument", cfg, *QUIET,
                     "--out", tmp_path / "runs")
    assert scan.returncode == 0, scan.stderr
    run, cal_path = run_dir_of(scan), tmp_path / "cal.json"
    build = gonio_cli("calibrate", "build", run, "--out", cal_path)
    assert build.returncode == 0, build.stderr
    # darks and gains on every range, the aperture from the run's [optics]: only the angles
    # (no --eta) are missing, and said so, on stderr and in the file
    assert build.stderr.splitlines() == [
        "gonio calibrate: angles: not calibrated: no eta of a reference sample (--eta, or the "
        "[sample] of a run with a specular scan)"]
    cal = calfile.load(cal_path)
    assert cal.notes == [build.stderr.removeprefix("gonio calibrate: ").strip()]
    assert sorted(cal.dark_offsets_w, key=float) == sorted(cal.gains, key=float) == ALL_RANGES
    assert cal.aperture_method == "geometry"
    assert cal.aperture_half_angle_deg.value == pytest.approx(0.5729, abs=1e-4)
    # asked for what the run cannot give: a non-zero exit and one line saying why
    for ask, why in ((["--eta", "1.51"], "angle calibration (--eta) needs a run with a "
                      "specular scan"),
                     (["--aperture-scan", run], f"--aperture-scan {run}: its sample readings "
                      "are at 2 sample angles")):
        proc = gonio_cli("calibrate", "build", run, "--out", tmp_path / "x.json", *ask)
        assert proc.returncode == 2 and why in proc.stderr
        one_line_error(proc.stderr)
    assert not (tmp_path / "x.json").exists()
    # every shipped sample plan on its instrument (all autorange, beam included: every range
    # of the meters, which all offer 1e-8 ... 1e-2 W) is covered
    for name in ("walter-antiglare", "walter-ground-glass", "walter-acid-etched", "demo",
                 "out-of-plane"):
        plan = load_plan(PLANS / f"{name}.toml")
        readings = build_schedule(plan, load_config(plan.instrument)).readings
        needed = ranges_read(readings, DEFAULT_RANGES_W)
        assert needed == list(DEFAULT_RANGES_W) and uncovered(cal, needed) == {}, name
    proc = gonio_cli("scan", PLANS / "walter-antiglare.toml", *QUIET, "--out",
                     tmp_path / "walter", "--calibration", cal_path)
    assert proc.returncode == 0, proc.stderr
    meta = json.loads((run_dir_of(proc) / "meta.json").read_text())
    assert meta["status"] == "completed"
    assert meta["calibration"]["file"] == str(cal_path.resolve())


def test_a_calibration_lacking_ranges_is_refused_before_the_run_exists(tmp_path):
    # an older detector calibration: two points of the lobe on 1e-7 and 1e-6 W only
    plan = write_toml(tmp_path / "old-calib.toml", {
        "name": "old-calib", "repeats": 3, "order": "as-written",
        "grid": [{"side": "transmission", "theta_i_deg": 0.0, "theta_o_deg": [20.0, 24.0],
                  "range": [1e-7, 1e-6]}],
        "dark": {"every": 6}, "beam": {"every": 12}})
    scan = gonio_cli("scan", plan, "--instrument", sim_serial(tmp_path), *QUIET,
                     "--out", tmp_path / "runs")
    assert scan.returncode == 0, scan.stderr
    old = tmp_path / "old.json"
    assert gonio_cli("calibrate", "build", run_dir_of(scan), "--out", old).returncode == 0
    # the Walter plan autoranges, its beam too: it can read on every range of the meter
    proc = gonio_cli("scan", PLANS / "walter-antiglare.toml", *QUIET,
                     "--out", tmp_path / "walter", "--calibration", old)
    assert proc.returncode == 2 and proc.stdout == ""
    one_line_error(proc.stderr)
    assert (f"calibration {old} does not cover the detector ranges the plan can read on "
            "(1e-08..0.01 W): it lacks 1e-08 W (dark offset, gain), 1e-05 W (dark offset, "
            "gain), 0.0001 W (dark offset, gain), 0.001 W (dark offset, gain), 0.01 W (dark "
            "offset, gain);") in proc.stderr
    assert not (tmp_path / "walter").exists()


def test_which_ranges_a_plan_can_read_on():
    # fixed ranges need the range the meter selects for them; autoranged readings every range
    # up to the beam readings' one, all of them when the beam autoranges
    cfg = load_config(EXAMPLES / "instruments" / "sim-serial.toml")

    def needed(**plan):
        raw = {"name": "p", "grid": [{"side": "reflection", "theta_i_deg": 20.0,
                                      "theta_o_deg": [10.0, 30.0]}],
               "dark": {"every": 2}, **plan}
        return ranges_read(build_schedule(parse_plan(raw), cfg).readings, DEFAULT_RANGES_W)

    assert needed(range=5e-7) == [1e-6]
    assert needed(range=1e-6, beam={"every": 2, "range": 1e-2}) == [1e-6, 1e-2]
    assert needed(range="auto", beam={"every": 2, "range": 1e-5}) == [1e-8, 1e-7, 1e-6, 1e-5]
    assert needed(range="auto", beam={"every": 2}) == list(DEFAULT_RANGES_W)
    assert needed(range=1e-6, beam={"every": 2, "range": "auto"}) == list(DEFAULT_RANGES_W)
    assert needed(range=1e-6) == [1e-6]  # no beam readings, nothing autoranged
