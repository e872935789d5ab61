"""Round trips on the emulated bench (ptys, ESP and PM100 emulators, scan engine, run store,
reduce): Walter's three samples measured, reduced and fitted at normal incidence; and the fit
on a misaligned, drifting bench after calibration against the fit on an ideal bench."""

import json
import math

import numpy as np
import pytest
from fitting_bench_runs import instrument, plan, scan
from mitsuba_reader import read_mitsuba
from zemax_cells import assert_measured_cells

from calibration import calfile
from calibration.calibrate import build
from calibration.exports.zemax import read_zemax
from calibration.fit import FitOptions
from calibration.pipeline import fit_run, reduce_run
from calibration.values import Measured
from gonio.store import open_run
from gonio_cli.main import main

SOURCE = {"power_w": 1e-3, "beam_diameter_mm": 2.0, "divergence_deg": 0.03}
APERTURE = {"diameter_mm": 10.0, "distance_mm": 500.0, "rtol": 1e-5}  # bench accuracy << noise


#: Walks per table of the bench's multiple scattering (where "auto" turns it on): 8x the fit's
#: refit, so their Monte Carlo error (which no sigma carries) stays well below the fit's own
#: and the chi-square tests the model, not the emulator's walks (plane_store keeps them).
BENCH_MS_WALKS = 1 << 24


def sample(distribution: str, alpha: float) -> dict:
    """The sample table of a round trip."""
    return {"kind": "hemisphere", "distribution": distribution, "alpha": alpha, "eta": 1.51,
            "ms_walks": BENCH_MS_WALKS}


def wide_lobe_grids() -> list[dict]:
    """Normal incidence finely (the fit), 30 and 60 degrees coarsely (held out)."""
    return [
        {"side": "transmission", "theta_i_deg": 0.0,
         "theta_o_deg": {"start": -70.0, "stop": 70.0, "step": 3.5}},
        {"side": "reflection", "theta_i_deg": 0.0,
         "theta_o_deg": {"start": 8.0, "stop": 80.0, "step": 6.0}},
        # the transmitted lobe at 60 deg ends in a hard edge near theta_o = 71 deg (no facet
        # refracts beyond it): an aperture straddling that discontinuity is not modelled to the
        # bench's 6e-4 precision by any low-order cap rule, so the held-out scan stops short
        {"side": "transmission", "theta_i_deg": [30.0, 60.0],
         "theta_o_deg": {"start": -70.0, "stop": 63.0, "step": 7.0}},
    ]


def narrow_lobe_grids() -> list[dict]:
    """The anti-glare peak is about half a degree wide in transmission: fine steps across it
    (the bench's far-tail readings of such a lobe are slow, and dark-limited anyway)."""
    return [
        {"side": "transmission", "theta_i_deg": 0.0,
         "theta_o_deg": {"start": -3.0, "stop": 3.0, "step": 0.15}},
        {"side": "transmission", "theta_i_deg": 30.0,
         "theta_o_deg": {"start": 16.5, "stop": 22.5, "step": 0.3}},
        {"side": "reflection", "theta_i_deg": 30.0,
         "theta_o_deg": {"start": 24.0, "stop": 36.0, "step": 0.6}},
    ]


#: (value - truth) / sigma of alpha over bench seeds (fit seed = bench seed): mean (the
#: estimator's bias) and spread. The anti-glare fit sits low (seeds 1-16, cause not traced:
#: single scattering, -0.002 % at most). The rough glasses, the bench's tables at 2^24 walks
#: and the fit as now (bench/walter_pulls.py, seeds 1-4): +0.05 +- 0.47 and +0.37 +- 0.58
#: (each mean's own error about spread / 2), where at 2^21 walks they were +0.20 +- 0.93 and
#: +0.66 +- 0.91 (seeds 1-8 in an earlier run: +0.57 +- 0.79 and +0.49 +- 1.01, the offsets
#: this test allowed before). The tolerance is ~3-4 spreads about the bias.
PULL_BIAS = {0.023: -1.52, 0.394: 0.05, 0.553: 0.37}
PULL_TOLERANCE = {0.023: 3.0, 0.394: 2.0, 0.553: 2.0}  # spreads 0.93, 0.47, 0.58


@pytest.mark.slow
@pytest.mark.timeout(900)  # a fresh machine walks the bench's tables first: 2-4 min a sample
@pytest.mark.parametrize("distribution,alpha", [
    ("beckmann", 0.023), ("ggx", 0.394), ("ggx", 0.553)])
def test_walter_samples_round_trip(distribution, alpha, tmp_path):
    cfg = instrument(tmp_path, {"source": SOURCE, "sample": sample(distribution, alpha),
                                "aperture": APERTURE}, seed=3)
    grids = narrow_lobe_grids() if alpha < 0.1 else wide_lobe_grids()
    run = scan(plan(tmp_path, f"walter-{distribution}", grids, dark_every=8), cfg,
               tmp_path / "runs")
    # the bench's default multiple_scattering = "auto" adds it for ground and etched glass
    # (energy lost above the detector's noise floor), not for the anti-glare glass: fit alike
    rough = alpha > 0.1
    data, result = fit_run(run, FitOptions(distributions=("beckmann", "ggx"),
                                           multiple_scattering=rough))
    value, sigma = result.param("alpha")
    assert result.distribution == distribution
    assert abs((value - alpha) / sigma - PULL_BIAS[alpha]) < PULL_TOLERANCE[alpha], value
    assert abs(value / alpha - 1.0) < 0.03
    # reduce's noise law (dark scatter scaled with the range, plus shot noise) and the beam
    # curve's shared error as a covariance; the noise level is estimated from 13 dark readings
    # (+-20 % in sigma, docs/fitting.md, so chi2 x 0.7-1.6 at one sigma of it). Over the 32
    # runs above: fitted 0.49-1.75 (mean 0.98, spread 0.36); held out 0.40-2.49, the most
    # for ground glass (mean 1.59, spread 0.47: its held-out incidences add the fit's walked
    # orders >= 2 and their Monte Carlo error). Bands: mean + 3 spreads above, 3/4 of the
    # least seen below. With multiple scattering (bench seeds 1-8, fit seeds 0 and = bench
    # seed) fitted 0.65-2.07 (mean 1.08-1.12) for ground glass and 0.75-1.82 (mean 1.17-1.39)
    # for the etched glass, held out 0.79-3.11 and 1.62-4.15 (mean 1.6-2.1 and 2.3: the
    # held-out incidences carry both sides' walked orders >= 3); bench seed 3 with fit seed 0,
    # asserted here (the bench's tables at 2^24 walks): 0.77 and 0.86 fitted, 1.68 and 2.62
    # held out, pulls -0.08 and +0.01. Tops 3.0 fitted and 4.0 held out.
    assert 0.3 < result.chi2_dof_fit < 3.0
    assert result.n_heldout > 10 and 0.3 < result.chi2_dof_heldout < (4.0 if rough else 3.0)
    # the CLI prints the same fit as one JSON object
    assert main(["fit", str(run), "--json", "--distribution", "beckmann,ggx"]
                + ["--multiple-scattering"] * rough) == 0


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    """Ground glass at normal incidence only (both sides). Bench seed 2: its multiple-
    scattering fit has chi2/dof 0.77 (seeds 2-5: 0.67-0.98 with the fit's term at the table's
    centre, before the refit at the result); seed 1's bench tables hold a heavy-tailed walk of
    the transmitted orders >= 3 (chi2/dof 4.2; 3.5 with 2^22 walks: keyed walks keep it),
    which the round trips' spread above includes. Its tables at 2^21 walks (a few seconds to
    walk on a fresh machine: this runs in the main suite)."""
    tmp = tmp_path_factory.mktemp("quick")
    cfg = instrument(tmp, {"source": SOURCE, "sample": dict(sample("ggx", 0.394),
                                                            ms_walks=1 << 21),
                           "aperture": APERTURE}, seed=2)
    return scan(plan(tmp, "quick", wide_lobe_grids()[:2]), cfg, tmp / "runs")


def test_fit_json_cli(quick_run, capsys):
    run = quick_run
    assert main(["fit", str(run), "--json", "--distribution", "ggx"]) == 0
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert out["distribution"] == "ggx"
    assert set(out["parameters"]["alpha"]) == {"value", "sigma"}
    assert out["chi2_dof_heldout"] is None and out["n_fit"] > 20
    assert main(["fit", str(run), "--distribution", "ggx,beckmann"]) == 0
    text = capsys.readouterr().out
    assert "run " in text and "alpha" in text and "clearly preferred" in text
    assert "emulator truth ([sim.sample]): ggx alpha 0.394, eta 1.51" in text
    assert "sample test-glass (hemisphere, eta 1.51)" in text
    assert main(["fit", str(run), "--incidence", "45"]) == 2  # one clear error line
    assert "usable points at incidence 45 deg" in capsys.readouterr().err


def test_fit_after_calibration_matches_ideal_bench(tmp_path):
    # single scattering on both benches: the fit here models only that
    ground_glass = dict(sample("ggx", 0.394), multiple_scattering=False)
    ideal = instrument(tmp_path, {"source": SOURCE, "sample": ground_glass,
                                  "aperture": APERTURE}, seed=5)
    faults = {"sample_offset_deg": 0.4, "arm_offset_deg": -0.3}
    # the source drifts on the run's virtual clock (its t_s clock), so the drift is followed
    # at any time_scale, "inf" included; a scan lasts a few hundred virtual seconds, over which
    # this drift (0.005 %/s at most) moves the beam by 1-3 %, twenty times its noise or more
    drifting = dict(SOURCE, drift_fraction=0.04, drift_period_s=4800.0)
    bad = instrument(tmp_path, {"source": drifting, "sample": ground_glass,
                                "aperture": APERTURE, "alignment": faults,
                                "detector": {"dark_current_a": 2e-10}}, seed=5)
    antiglare = instrument(tmp_path, {"source": drifting,
                                      "sample": dict(sample("beckmann", 0.023),
                                                     multiple_scattering=False),
                                      "aperture": APERTURE, "alignment": faults,
                                      "detector": {"dark_current_a": 2e-10}}, seed=6)
    calib_plan = plan(tmp_path, "calib-angles", [
        {"side": "transmission", "theta_i_deg": 0.0,
         "theta_o_deg": {"start": -2.5, "stop": 2.5, "step": 0.25}},
        {"side": "reflection", "theta_i_deg": 10.0,
         "theta_o_deg": {"start": 2.0, "stop": 18.0, "step": 0.5}},
    ], repeats=2, dark_every=12, beam_every=6)
    calib_run = open_run(scan(calib_plan, antiglare, tmp_path / "runs"))
    half_angle = math.degrees(math.atan(0.5 * APERTURE["diameter_mm"] / APERTURE["distance_mm"]))
    cal = build([calib_run.readings()], "2026-11-23T13:00:00Z", [str(calib_run.path)],
                eta=1.51, aperture=(Measured(0.0, 0.0), Measured(half_angle, 0.0), "geometry"),
                divergence_deg=SOURCE["divergence_deg"])
    # the angle fit's pulls over bench seeds: test_calibration_emulated_bench.py's
    # PULL_TOLERANCE
    for measured, truth in ((cal.sample_offset_deg, 0.4), (cal.arm_offset_deg, -0.3)):
        assert abs(measured.pull(truth)) < 4.0 and measured.sigma < 1e-4
    cal_path = calfile.save(cal, tmp_path / "cal.json")
    measure = plan(tmp_path, "ground-glass", wide_lobe_grids(), beam_every=10)
    ideal_run = scan(measure, ideal, tmp_path / "runs")
    bad_run = scan(measure, bad, tmp_path / "runs")
    assert main(["calibrate", "use", str(bad_run), str(cal_path)]) == 0
    options = FitOptions(distributions=("ggx",))
    _, reference = fit_run(ideal_run, options)
    data, calibrated = fit_run(bad_run, options)
    assert data.meta["calibration"]["sha256"] == calfile.reference(cal_path)["sha256"]
    a_ref, s_ref = reference.param("alpha")
    a_cal, s_cal = calibrated.param("alpha")
    assert abs(a_cal - a_ref) < 3.0 * np.hypot(s_ref, s_cal)
    # the calibrated bench predicts the held-out incidences as well as the ideal one: the
    # drift's beam curve and its errors shared by every reading are part of the reduction
    # (docs/fitting.md, "Calibrated against ideal bench")
    assert reference.chi2_dof_heldout < 1.5 and calibrated.chi2_dof_heldout < 1.5


def test_export_cli_of_family_fits(quick_run, tmp_path, capsys):
    """`gonio export --fit` of a model family's fit: an ABg fit as OpticStudio's ABg entry
    (the file's path printed), an Oren-Nayar fit refused by Mitsuba in one line naming the
    formats that take it, nothing written."""
    fit = {"chi2_dof_fit": 1.2, "n_fit": 40, "chi2_dof_heldout": None, "n_heldout": 0}
    (tmp_path / "abg.json").write_text(json.dumps({**fit, "family": "abg", "parameters": {
        "A": {"value": 1e-3, "sigma": 1e-5}, "B": {"value": 2e-4, "sigma": 1e-6},
        "g": {"value": 2.1, "sigma": 0.02}}}) + "\n")
    assert main(["export", str(quick_run), "--format", "abg", "--fit",
                 str(tmp_path / "abg.json"), "--out", str(tmp_path / "paint.abg")]) == 0
    assert capsys.readouterr().out.split() == [str(tmp_path / "paint.abg")]
    lines = (tmp_path / "paint.abg").read_text().splitlines()
    assert "Name  PAINT" in lines and "Row  1  0.0  0.001  0.0002  2.1" in lines
    (tmp_path / "on.json").write_text(json.dumps({**fit, "family": "oren-nayar", "parameters": {
        "rho": {"value": 0.6, "sigma": 0.01}, "sigma": {"value": 0.3, "sigma": 0.01}}}))
    assert main(["export", str(quick_run), "--format", "mitsuba", "--fit",
                 str(tmp_path / "on.json"), "--out", str(tmp_path / "on.xml")]) == 2
    assert capsys.readouterr().err == (
        "gonio export: error: export: --format mitsuba has no form of the oren-nayar family; a "
        "oren-nayar fit exports as --format zemax or astm (zemax and astm tabulate it)\n")
    assert not (tmp_path / "on.xml").exists()


def test_export_and_plot_cli(quick_run, tmp_path, capsys):
    """Walter's ground glass (the bench adds multiple scattering): the default single-
    scattering fit does not describe it, so a model export refuses it; its multiple-scattering
    fit from `gonio fit --json` exports, and the Zemax file's measured blocks are the reduced
    data where measured."""
    assert main(["export", str(quick_run), "--format", "mitsuba",
                 "--out", str(tmp_path / "bad.xml")]) == 2
    assert "does not describe the data" in capsys.readouterr().err
    assert not (tmp_path / "bad.xml").exists()
    assert main(["fit", str(quick_run), "--json", "--distribution", "ggx",
                 "--multiple-scattering"]) == 0
    line = capsys.readouterr().out.strip().splitlines()[-1]
    (tmp_path / "fit.json").write_text(line + "\n")
    fitted = json.loads(line)
    alpha = fitted["parameters"]["alpha"]["value"]
    assert fitted["chi2_dof_fit"] < 3.0 and fitted["multiple_scattering"]
    assert main(["export", str(quick_run), "--format", "mitsuba", "--fit",
                 str(tmp_path / "fit.json"), "--out", str(tmp_path / "glass.xml")]) == 0
    assert capsys.readouterr().out.split() == [str(tmp_path / "glass.xml"),
                                               str(tmp_path / "gonio_mitsuba_plugin.py")]
    material = read_mitsuba(tmp_path / "glass.xml")
    assert material["type"] == "gonio_multiscatter"  # the multiple scattering, carried
    single = material["nested"]["single"]
    assert single["type"] == "roughdielectric"
    assert single["params"]["distribution"] == fitted["distribution"] == "ggx"
    assert single["params"]["alpha"] == pytest.approx(alpha, rel=1e-8)
    assert main(["export", str(quick_run), "--format", "mitsuba", "--fit",
                 str(tmp_path / "fit.json"), "--single-scattering",
                 "--out", str(tmp_path / "single.xml")]) == 0
    said = capsys.readouterr().err
    assert "single scattering only: the material drops the fit's multiple scattering" in said
    assert read_mitsuba(tmp_path / "single.xml")["type"] == "roughdielectric"
    assert main(["export", str(quick_run), "--format", "zemax", "--fit",
                 str(tmp_path / "fit.json"), "--out", str(tmp_path / "glass.bsdf")]) == 0
    assert capsys.readouterr().out.split() == [str(tmp_path / "glass.bsdf"),
                                               str(tmp_path / "glass-BRDF.bsdf")]
    btdf, brdf = read_zemax(tmp_path / "glass.bsdf"), read_zemax(tmp_path / "glass-BRDF.bsdf")
    assert (btdf.scatter_type, brdf.scatter_type) == ("BTDF", "BRDF")
    assert btdf.source == brdf.source == "Measured"
    assert list(btdf.angle_deg) == [0.0] and 0.0 < btdf.tis[0, 0] < 1.0
    assert any(f"alpha = {alpha:.6g}" in c for c in btdf.comments)
    assert any(c.startswith("block AngleOfIncidence 0 ") and "measured at" in c
               for c in btdf.comments)
    data = reduce_run(quick_run)
    for table in (btdf, brdf):
        assert_measured_cells(table, data.subset(data.valid & (
            data.transmission == (table.scatter_type == "BTDF"))))
    assert main(["plot", str(quick_run), "--fit", "--distribution", "ggx",
                 "--out", str(tmp_path / "fit.png")]) == 0
    assert (tmp_path / "fit.png").read_bytes()[:4] == b"\x89PNG"
