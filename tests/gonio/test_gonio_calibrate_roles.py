"""Calibration that is right or refuses, as a user meets it on the emulated bench (real
emulators on ptys, the real CLI): the README's `gonio calibrate build CAL_RUN... --out cal.json`
with the three shipped calibration runs, each run routed by what its plan calibrates; a run in
the wrong role gets one line naming the flag or run it needs; an angle fit the model does not
describe, or from a sample the plan does not name a reference, is refused (exit 2, nothing
written) unless --force; `gonio scan --calibration` prints what it applies."""

import pytest
from gonio_testkit import (
    EXAMPLES,
    gonio_cli,
    load_example,
    one_line_error,
    run_dir_of,
    scan_messages,
    write_toml,
)

from calibration import calfile
from gonio.store import open_run

PLANS = EXAMPLES / "plans"
QUIET = ("--sim", "--time-scale", "inf", "--no-plot", "--no-progress")


def scanned(plan, out, *options) -> str:
    """The run directory of a completed emulated scan of `plan`."""
    proc = gonio_cli("scan", plan, *QUIET, "--out", out, *options)
    assert proc.returncode == 0, proc.stderr
    return str(run_dir_of(proc))


def refused(proc, *parts: str) -> str:
    """The one error line of a refused build (exit 2), holding each of `parts`."""
    assert proc.returncode == 2, proc.stderr
    line = one_line_error(proc.stderr)
    for part in parts:
        assert part in line, line
    return line


@pytest.mark.slow
def test_the_readme_line_builds_from_the_three_shipped_runs(tmp_path):
    runs = {kind: scanned(PLANS / f"calib-{kind}.toml", tmp_path / kind)
            for kind in ("angles", "aperture", "detector")}
    cal_path = tmp_path / "cal.json"
    build = gonio_cli("calibrate", "build", *runs.values(), "--out", cal_path)
    assert build.returncode == 0, build.stderr
    assert build.stdout.strip() == str(cal_path)
    assert "warning" not in build.stderr and build.stderr == ""
    cal = calfile.load(cal_path)
    # the angle run gave the offsets (sim-serial's bench has none: truth 0), on the smooth
    # reference its plan names, whose model fits the peaks
    assert cal.angle_fit["distribution"] == "beckmann" and cal.angle_fit["chi2_dof"] < 3.0
    assert abs(cal.angle_fit["alpha"]["value"] / 0.023 - 1.0) < 1e-3
    for offset in (cal.sample_offset_deg, cal.arm_offset_deg):
        assert abs(offset.pull(0.0)) < 3.0 and offset.sigma < 1e-4
    # the aperture run the aperture (10 mm at 500 mm), the detector run darks and gains on all
    # seven ranges, each fit within its chi2/dof bound
    assert cal.aperture_method == "beam-scan"
    assert cal.aperture_half_angle_deg.value == pytest.approx(0.5729, abs=2e-3)
    assert len(cal.gains) == len(cal.dark_offsets_w) == 7
    assert cal.linearity["chi2_dof"] < 3.0

    # wrong roles: one line naming the run or flag needed, nothing written
    wrong = tmp_path / "wrong.json"
    refused(gonio_cli("calibrate", "build", runs["detector"], "--aperture-scan", runs["angles"],
                      "--out", wrong),
            f"--aperture-scan {runs['angles']}: its sample readings are at 3 sample angles",
            "the run calibrates the angles (its plan's calibrates = 'angles'): give it as a RUN, "
            "and as --aperture-scan a run of examples/plans/calib-aperture.toml")
    refused(gonio_cli("calibrate", "build", runs["aperture"], "--aperture-geometry", "10", "500",
                      "--out", wrong),
            f"{runs['aperture']} scans the aperture", "--aperture-geometry gives it too")
    assert not wrong.exists()

    # a scan with the calibration says what it applies, once it covers the plan's ranges
    plan = write_toml(tmp_path / "two-points.toml", {
        "name": "two-points", "range": 1e-6,
        "grid": [{"side": "transmission", "theta_i_deg": 0.0, "theta_o_deg": [20.0, 24.0]}]})
    proc = gonio_cli("scan", plan, "--instrument", EXAMPLES / "instruments" / "sim-serial.toml",
                     *QUIET, "--out", tmp_path / "measured", "--calibration", cal_path)
    assert proc.returncode == 0, proc.stderr
    lines = scan_messages(proc.stderr)
    off = cal.sample_offset_deg
    assert lines[:5] == [
        f"gonio scan: calibration {cal_path} (created {cal.created_utc}) applies:",
        f"gonio scan:   angle offsets: sample {off.value:.6g} +- {off.sigma:.2g} deg, arm "
        f"{cal.arm_offset_deg.value:.6g} +- {cal.arm_offset_deg.sigma:.2g} deg",
        lines[2], lines[3],
        f"gonio scan:   aperture: half-angle {cal.aperture_half_angle_deg.value:.6g} +- "
        f"{cal.aperture_half_angle_deg.sigma:.2g} deg, solid angle "
        f"{cal.aperture_solid_angle_sr.value:.6g} +- {cal.aperture_solid_angle_sr.sigma:.2g} sr "
        "(beam-scan)"]
    assert lines[2].startswith("gonio scan:   dark offsets: 1e-08 W: ")
    assert lines[2].count(" W: ") == 7
    assert lines[3].startswith("gonio scan:   gains: 1e-08 W: ")
    assert lines[3].endswith("0.01 W: 1 +- 0 (relative to 0.01 W)")


def angle_plan(tmp_path, sample_id: str, reference: bool) -> str:
    """calib-angles with fewer points (its grids' steps doubled), mounting `sample_id` of
    sim-serial's cabinet, its [sample] naming it an angle reference or not."""
    import tomllib

    plan = tomllib.loads((PLANS / "calib-angles.toml").read_text())
    plan["instrument"] = str(EXAMPLES / "instruments" / "sim-serial.toml")
    plan["repeats"] = 2
    for grid in plan["grid"]:
        grid["theta_o_deg"]["step"] *= 2
    plan["sample"]["id"] = sample_id
    if not reference:
        del plan["sample"]["reference"]
    return write_toml(tmp_path / f"{sample_id}-{reference}.toml", plan)


def test_an_angle_fit_on_the_ground_glass_is_refused_unless_forced(tmp_path):
    # the plan mounts sim-serial's diffuse reference and does not name it an angle reference:
    # its peaks hold the multiple scattering the fit's single-scattering model lacks, and the
    # fit misses them by far more than their noise
    run = scanned(angle_plan(tmp_path, "reference-ground-glass", reference=False), tmp_path)
    cal_path = tmp_path / "cal.json"
    line = refused(gonio_cli("calibrate", "build", run, "--out", cal_path),
                   "gonio calibrate: error: angles: the zero-offset fit has chi2/dof ",
                   f"angles: the [sample] of {run} is not named a reference for them "
                   '([sample] reference = "angles"',
                   ": nothing written (--force writes it)")
    chi2 = float(line.split("chi2/dof ")[1].split(" ")[0])
    assert chi2 > 3.0
    assert not cal_path.exists()
    forced = gonio_cli("calibrate", "build", run, "--out", cal_path, "--force")
    assert forced.returncode == 0, forced.stderr
    assert f"angles: warning: the zero-offset fit has chi2/dof {chi2:.3g} > 3" in forced.stderr
    assert f"angles: warning: the [sample] of {run} is not named a reference" in forced.stderr
    assert calfile.load(cal_path).angle_fit["chi2_dof"] == pytest.approx(chi2, rel=1e-2)


def test_an_angle_fit_from_a_sample_not_named_a_reference_is_refused(tmp_path):
    # the smooth reference, fitting well, but the plan does not say it is one
    run = scanned(angle_plan(tmp_path, "reference-antiglare", reference=False), tmp_path)
    line = refused(gonio_cli("calibrate", "build", run, "--out", tmp_path / "cal.json"),
                   f"gonio calibrate: error: angles: the [sample] of {run} is not named a "
                   "reference for them")
    assert "chi2/dof" not in line and not (tmp_path / "cal.json").exists()


def test_an_untagged_beam_scan_is_pointed_to_aperture_scan(tmp_path):
    # a plan of one's own scanning the arm across the beam, saying nothing of what it calibrates
    plan = write_toml(tmp_path / "my-beam-scan.toml", {
        "name": "my-beam-scan", "instrument": str(EXAMPLES / "instruments" / "sim-serial.toml"),
        "grid": [{"side": "transmission", "theta_i_deg": 90.0,
                  "theta_o_deg": {"start": 89.5, "stop": 90.0, "step": 0.1}}],
        "dark": {"every": 3},
        "sample": {"id": "reference-antiglare", "kind": "hemisphere", "eta": 1.51}})
    run = scanned(plan, tmp_path)
    assert open_run(run).plan.get("calibrates") is None
    refused(gonio_cli("calibrate", "build", run, "--out", tmp_path / "cal.json"),
            f"{run}: its sample readings all have the sample edge-on, an arm scan across the "
            f"beam: give it as --aperture-scan {run} (or set calibrates = \"aperture\" in its "
            "plan)")


def test_the_cabinet_mounts_the_plan_sample_in_the_emulator_truth():
    # what reduce and plots draw as the emulator's truth is the sample the plan mounted
    from sim.truth import EmulatorTruth

    sim = load_example("sim-serial")["sim"]
    antiglare = EmulatorTruth(sim, None, {"id": "reference-antiglare", "kind": "hemisphere",
                                          "eta": 1.51})
    assert antiglare.sample["distribution"] == "beckmann" and antiglare.sample["alpha"] == 0.023
    other = EmulatorTruth(sim, None, {"id": "my-glass", "kind": "hemisphere", "eta": 1.51})
    assert other.sample["distribution"] == "ggx" and other.sample["alpha"] == 0.394
