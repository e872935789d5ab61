"""The GUM budget of reduced values (calibration.budget, calibration.reduce): components that
combine into sigma, shared parts that enter the fit's covariance, angle terms through the fitted
model's slope checked by an independent derivative, and the coverage of U = 2 u on synthetic raw
readings whose every error is drawn from its own process (tests/fitting/budget_kit.py)."""

from __future__ import annotations

import dataclasses
import math
import tomllib

import numpy as np
import pytest
from budget_kit import Scan, run_of, spec_config, spec_run, spec_scan
from fitting_bench_runs import EXAMPLE, instrument, plan, scan

from calibration.budget import AngleInputs, Budget, expanded
from calibration.fit import FitOptions, fit
from calibration.pipeline import DEFAULT_SLOPE_FIT, slope_fit_options
from calibration.reduce import optics_of, range_columns, reduce_readings
from calibration.values import CalibrationError, Measured
from gonio.config import parse_config
from gonio.device_kinds.specs import ESP, PM100, ZABER
from gonio.errors import ConfigError
from gonio.optics import Optics

SCAN = Scan()


def reduced(scan: Scan, seed: int, slope: bool = True, **changes):
    """(ReducedData, truth) of one synthetic scan: reduced once, fitted (one distribution, the
    scan's incidence), reduced again with the fitted model's slope (calibration.pipeline)."""
    readings, truth = scan.draw(seed)
    run, cal = run_of(scan), scan.calibration()
    data = reduce_readings(run, readings, cal, scan.optics(), **changes)
    if not slope:
        return data, truth
    result = fit(data, FitOptions(distributions=(scan.distribution,),
                                  fit_incidence_deg=(scan.theta_i_deg,)))
    return reduce_readings(run, readings, cal, scan.optics(), slope_model=result.predict,
                           **changes), truth


def test_components_combine_into_sigma_and_the_shared_ones_into_shared_rel():
    data, _ = reduced(SCAN, 0)
    ok = data.valid
    assert set(data.components) == {"read_noise", "shot_noise", "dark", "beam_normalisation",
                                    "range_gain", "linearity", "solid_angle",
                                    "angle_repeatability", "angle_offset"}
    squares = sum(u**2 for u in data.components.values())
    np.testing.assert_allclose(data.sigma[ok] ** 2, squares[ok], rtol=1e-12)
    # the sample stage's scatter is shared by the readings between two of its moves (a beam
    # reading), the arm's is each reading's own
    assert set(data.meta["budget"]["shared"]) == {"dark", "beam_normalisation", "range_gain",
                                                  "solid_angle", "angle_offset",
                                                  "angle_repeatability"}
    assert set(data.meta["budget"]["own"]) == {"read_noise", "shot_noise", "linearity",
                                               "angle_repeatability"}
    own = sum(data.components[n] ** 2 for n in ("read_noise", "shot_noise", "linearity"))
    assert np.all(data.sigma_own[ok] ** 2 >= own[ok] * (1 - 1e-9))
    assert np.all(data.sigma_own[ok] ** 2
                  <= (own + data.components["angle_repeatability"] ** 2)[ok] * (1 + 1e-9))
    # a column per range for dark and gain, the beam curve's (a line at least), one for the
    # solid angle, one per calibrated stage offset
    assert data.shared_rel.shape[1] >= 1 + 2 + 1 + 1 + 2
    k, big_u = expanded(data)
    assert k == 2.0 and np.array_equal(big_u, 2.0 * data.sigma)


def test_whitened_chi_square_is_the_full_covariance_of_the_components():
    """Sum of squares of `whitened` at the data's own values equals r^T C^-1 r with
    C = diag(own^2) + S S^T built from the shared components' absolute errors."""
    data, _ = reduced(SCAN, 1)
    data = data.subset(data.valid)
    model = data.bsdf * (1.0 + 1e-3)  # any model near the data
    s = model[:, None] * data.shared_rel
    cov = np.diag(data.sigma_own**2) + s @ s.T
    r = model - data.bsdf
    direct = float(r @ np.linalg.solve(cov, r))
    assert float(np.sum(data.whitened(model) ** 2)) == pytest.approx(direct, rel=1e-8)


def test_angle_terms_match_the_true_models_derivative():
    """The repeatability term per stage: |df/dstage| r, with the slope from the fitted model
    against a derivative of the generating model by a different step (1e-4 deg)."""
    one = Scan(repeatability_deg=(5e-3, 0.0), offset_sigma_deg=(0.0, 0.0))
    data, _ = reduced(one, 2)
    readings, _ = one.draw(2)
    rows = readings[readings["kind"] == "sample"]
    h = 1e-4
    up, _ = one.reading_model(rows["sample_deg"] + h, rows["arm_deg"], one.half_angle_deg)
    down, _ = one.reading_model(rows["sample_deg"] - h, rows["arm_deg"], one.half_angle_deg)
    _, cos_factor = one.reading_model(rows["sample_deg"], rows["arm_deg"], one.half_angle_deg)
    expected = np.abs((up - down) / (2 * h) / cos_factor) * 5e-3
    ok = data.valid & (expected > 1e-3 * data.bsdf)
    assert ok.sum() > 40
    np.testing.assert_allclose(data.components["angle_repeatability"][ok], expected[ok],
                               rtol=0.02)
    assert "angle_offset" not in data.components


def test_without_a_fitted_model_the_angle_terms_are_left_out_and_said_so():
    data, _ = reduced(SCAN, 3, slope=False)
    assert "angle_repeatability" not in data.components
    assert any(n.startswith("angle: not propagated") for n in data.meta["budget"]["notes"])


def test_without_calibration_or_stated_errors_the_budget_is_the_noise_dark_and_beam():
    plain = Scan(repeatability_deg=(0.0, 0.0), linearity=0.0)
    readings, _ = plain.draw(4)
    data = reduce_readings(run_of(plain), readings, None, plain.optics())
    assert set(data.components) == {"read_noise", "shot_noise", "dark", "beam_normalisation"}
    assert data.meta["budget"]["notes"] == [
        "linearity: not stated ([detector] linearity_rel)", "range_gain: no calibration applied",
        "solid_angle: the calibration aperture states no uncertainty"]
    assert data.meta["budget"]["angle_inputs"] == {"repeatability_deg": {},
                                                   "offset_sigma_deg": {}}


def test_budget_keeps_zero_and_non_finite_values_out_of_shared_rel():
    b = Budget(np.array([2.0, 0.0, np.nan]))
    b.add_own("noise", np.array([0.1, 0.2, 0.3]))
    b.add_shared("gain", np.array([0.02, 0.01, 0.5]))
    np.testing.assert_allclose(b.shared_rel[:, 0], [0.01, 0.0, 0.0])
    np.testing.assert_allclose(b.sigma, np.hypot([0.1, 0.2, 0.3], [0.02, 0.01, 0.5]))


def test_angle_inputs_from_the_config_and_the_calibration():
    cal = SCAN.calibration()
    inputs = AngleInputs.of_run({"axes": {"sample": {"repeatability_deg": 0.002},
                                          "arm": {"device": "esp"}}}, cal)
    assert inputs.repeatability_deg == {"sample": 0.002}
    assert inputs.offset_sigma_deg == {"sample": 3e-3, "arm": 3e-3}
    assert not AngleInputs.of_run({}, None).any


def test_repeatability_and_linearity_are_keys_of_the_instrument_config():
    raw = tomllib.loads(EXAMPLE.read_text())
    assert parse_config(raw).axes["arm"].repeatability_deg == 0.0
    assert parse_config(raw).detector.linearity_rel is None
    raw["axes"]["arm"]["repeatability_deg"] = 0.004
    raw["detector"]["linearity_rel"] = 0.002
    config = parse_config(raw)
    assert config.axes["arm"].repeatability_deg == 0.004
    assert config.detector.linearity_rel == 0.002
    raw["axes"]["arm"]["repeatability_deg"] = -1.0
    with pytest.raises(ConfigError) as err:
        parse_config(raw)
    assert "[axes.arm] repeatability_deg" in str(err.value) and "\n" not in str(err.value)


@pytest.mark.slow
def test_coverage_of_U_at_k2_over_the_lobe_and_its_flanks():
    """40 synthetic scans (82 points each, across the reflected and refracted lobes of Beckmann
    0.05 at 30 deg): the share of values within U = 2 u of the truth, by where they sit on
    the lobe. Statistical (the shared components correlate a scan's values); ~12 s."""
    inside, where, blind = [], [], []
    for seed in range(40):
        data, truth = reduced(SCAN, seed)
        ok = data.valid
        peak = np.array([truth[data.transmission == t].max() for t in data.transmission])
        rel = (truth / peak)[ok]
        inside.append(np.abs(data.bsdf - truth)[ok] <= 2.0 * data.sigma[ok])
        where.append(np.where(rel > 0.3, "lobe", np.where(rel > 0.01, "flank", "tail")))
        no_angle, _ = reduced(SCAN, seed, slope=False)
        blind.append(np.abs(no_angle.bsdf - truth)[ok] <= 2.0 * no_angle.sigma[ok])
    inside, where, blind = map(np.concatenate, (inside, where, blind))
    for part in ("lobe", "flank", "tail"):
        sel = where == part
        assert sel.sum() > 500
        assert 0.92 <= inside[sel].mean() <= 0.98, (part, inside[sel].mean())
    # the test can fail: without the angle terms the flanks are far from covered
    assert blind[where == "flank"].mean() < 0.8
    assert math.isclose(inside.mean(), 0.95, abs_tol=0.02)


REPEATABILITY_DEG = 0.01


@pytest.fixture(scope="module")
def jittery_run(tmp_path_factory):
    """A scan across Beckmann 0.05's transmitted lobe on the emulated stack (ESP and PM100 on
    ptys) whose stages end each move N(0, 0.01 deg) off ([sim.alignment]), as the config's
    [axes] repeatability_deg says (and, as instrument() writes it, the emulated meter's and
    aperture's exact figures)."""
    tmp = tmp_path_factory.mktemp("budget")
    cfg = instrument(tmp, {"source": {"power_w": 1e-3}, "aperture": {"rtol": 1e-5},
                           "sample": {"kind": "hemisphere", "distribution": "beckmann",
                                      "alpha": 0.05, "eta": 1.51,
                                      "multiple_scattering": False},
                           "alignment": {"sample_repeatability_deg": REPEATABILITY_DEG,
                                         "arm_repeatability_deg": REPEATABILITY_DEG}}, seed=3)
    grids = [{"side": "transmission", "theta_i_deg": 0.0,
              "theta_o_deg": {"start": -4.0, "stop": 4.0, "step": 0.2}}]
    return scan(plan(tmp, "jitter", grids, dark_every=8, beam_every=8), cfg, tmp / "runs")


@pytest.mark.slow
def test_emulated_stage_scatter_is_covered_by_the_budget(jittery_run):
    """The reduced values against the bench at the reported positions: with the angle terms
    the pulls are those of a normal law, without them the flanks are many sigma off."""
    from calibration.pipeline import reduce_run
    from gonio.store import open_run
    from sim.bench import build_bench

    run = open_run(jittery_run)
    bench = build_bench(run.config["sim"], run.config["optics"], run.plan["sample"])
    rows = run.readings()
    rows = rows[rows["kind"] == "sample"]
    expected = bench.reduced_bsdf(rows["sample_deg"], rows["arm_deg"])
    data = reduce_run(jittery_run, slope_options=FitOptions(distributions=("beckmann",)))
    ok = data.valid & (expected > 1e-3 * expected.max())
    assert ok.sum() >= 20 and data.meta["budget"]["slope"]["distribution"] == "beckmann"
    pull = ((data.bsdf - expected) / data.sigma)[ok]
    assert 0.5 < np.sqrt(np.mean(pull**2)) < 1.6, pull
    assert np.mean(np.abs(pull) <= 2.0) >= 0.85
    blind = reduce_run(jittery_run, slope_options=None)
    blind_pull = ((blind.bsdf - expected) / blind.sigma)[ok]
    assert np.sqrt(np.mean(blind_pull**2)) > 5.0


@pytest.mark.slow
def test_gonio_reduce_reports_u_k_and_U(jittery_run, capsys):
    from gonio_cli.main import main

    assert main(["reduce", str(jittery_run), "--coverage-k", "3"]) == 0
    out = capsys.readouterr().out
    assert "k = 3, U = k u" in out and "angle_repeatability" in out
    lines = [ln for ln in (jittery_run / "reduced.csv").read_text().splitlines()
             if not ln.startswith("#")]  # the record and the facts (gonio export's CSV)
    table = np.genfromtxt(lines, delimiter=",", names=True, dtype=None, encoding=None)
    np.testing.assert_allclose(table["U"], 3.0 * table["sigma"], rtol=1e-12)
    assert set(table["k"]) == {3.0}
    assert main(["reduce", str(jittery_run), "--coverage-k", "0"]) != 0
    assert "--coverage-k must be a finite number > 0" in capsys.readouterr().err


def at_specs(scan: Scan, seed: int, calibrated: bool):
    """(ReducedData, truth) of a synthetic scan of the declared bench (budget_kit.spec_run):
    reduced with the kinds' type-B figures, fitted over every incidence as the pipeline's
    slope fit is (slope_fit_options of DEFAULT_SLOPE_FIT, one distribution), reduced again
    with its slope."""
    readings, truth = scan.draw(seed)
    run = spec_run(scan)
    cal = scan.calibration() if calibrated else None
    optics = optics_of(run.config, cal, run.plan)
    data = reduce_readings(run, readings, cal, optics)
    result = fit(data, slope_fit_options(dataclasses.replace(
        DEFAULT_SLOPE_FIT, distributions=(scan.distribution,))))
    return reduce_readings(run, readings, cal, optics, slope_model=result.predict), truth


#: (incidence, calibrated) of the coverage table in docs/fitting.md, "Coverage".
CASES = ((0.0, True), (0.0, False), (30.0, True), (30.0, False))


#: A seed's share of values within U scatters about the mean by this much (the standard
#: deviation over 400 seeds per case): the shared components (uncalibrated, the aperture's
#: tolerance above all) move a scan's ~80 values together, so the error of a mean share is this
#: over sqrt(seeds), far above the binomial sqrt(p (1 - p) / values) (~0.06 % at 400 seeds).
SEED_SCATTER = {True: 0.085, False: 0.155}  # calibrated, uncalibrated
#: The share the issue asks for: 95 % +- 1.5 %.
COVERAGE_BAND = (0.935, 0.965)


def coverage(seeds: range, cases=CASES) -> dict[tuple[float, bool], np.ndarray]:
    """Per case, each seed's share of values within U = 2 u of the truth."""
    out = {}
    for theta_i, calibrated in cases:
        scan = spec_scan(theta_i, calibrated)
        shares = []
        for seed in seeds:
            data, truth = at_specs(scan, seed, calibrated)
            ok = data.valid
            shares.append(np.mean(np.abs(data.bsdf - truth)[ok] <= 2.0 * data.sigma[ok]))
        out[theta_i, calibrated] = np.array(shares)
    return out


def test_type_b_terms_come_from_the_declared_specifications_with_their_sources():
    scan = spec_scan(30.0, calibrated=False)
    data, _ = at_specs(scan, 0, calibrated=False)
    assert {"linearity", "range_gain", "solid_angle", "angle_repeatability"} <= set(
        data.components)
    sources = data.meta["budget"]["sources"]
    assert "PM100USB" in sources["range_gain"] and "S120C" in sources["linearity"]
    assert "ISO 2768" in sources["solid_angle"] and "URS" in sources["angle_repeatability"]
    ok = data.valid
    np.testing.assert_allclose(data.components["linearity"][ok],
                               np.abs(data.bsdf[ok]) * 0.005 / math.sqrt(3.0))
    # without normal incidence the angle terms are there: the slope fit takes every incidence
    assert data.meta["budget"]["angle_inputs"]["repeatability_deg"] == {
        "sample": ESP.repeatability_deg.sigma, "arm": ESP.repeatability_deg.sigma}
    # a calibration's gains and measured aperture replace the spec's and the tolerance's
    calibrated, _ = at_specs(spec_scan(30.0, calibrated=True), 0, calibrated=True)
    sources = calibrated.meta["budget"]["sources"]
    assert sources["range_gain"] == "the calibration's range gains"
    assert sources["solid_angle"] == "the calibration's measured aperture"
    assert sources["linearity"] == data.meta["budget"]["sources"]["linearity"]


def test_a_geometry_aperture_in_a_calibration_keeps_the_tolerance_term():
    """A calibration whose aperture is the nominal geometry (gonio calibrate build without an
    aperture scan: sigma 0) did not measure it: its uncertainty stays the tolerance."""
    scan = spec_scan(30.0, calibrated=True)
    readings, _ = scan.draw(0)
    run = spec_run(scan)
    half = scan.half_angle_deg
    for cal in (dataclasses.replace(scan.calibration(), aperture_method="geometry",
                                    aperture_half_angle_deg=Measured(half, 0.0)),
                dataclasses.replace(scan.calibration(), aperture_method="beam-scan",
                                    aperture_half_angle_deg=Measured(half, 0.0))):
        optics = optics_of(run.config, cal, run.plan)
        data = reduce_readings(run, readings, cal, optics)
        assert optics.aperture_from == "calibration"
        assert "ISO 2768-1 table 1" in data.meta["budget"]["sources"]["solid_angle"]
        ok = data.valid
        np.testing.assert_allclose(data.components["solid_angle"][ok],
                                   np.abs(data.bsdf[ok]) * optics.solid_angle_rel)
        assert optics.solid_angle_rel > 0


def test_the_configs_own_figures_win_over_the_kinds():
    scan = spec_scan(30.0, calibrated=False)
    config = spec_config(scan)
    config["detector"].update(linearity_rel=1e-3, range_gain_rel=2e-4)
    config["axes"]["arm"]["repeatability_deg"] = 0.0  # stated: a perfect arm
    config["optics"]["aperture_diameter_tolerance_mm"] = 0.005
    optics = optics_of(config, None, spec_run(scan).plan)
    assert (optics.linearity_rel, optics.range_gain_rel) == (1e-3, 2e-4)
    assert optics.sources["linearity"] == "the config's [detector] linearity_rel"
    assert "aperture_diameter_tolerance_mm" in optics.sources["solid_angle"]
    # Omega ~ d^2: twice the diameter's relative sigma
    assert optics.solid_angle_rel == pytest.approx(2 * 0.005 / math.sqrt(3) / 3.5, rel=1e-3)
    inputs = AngleInputs.of_run(config)
    assert inputs.repeatability_deg == {"sample": ESP.repeatability_deg.sigma}


def test_a_figure_stated_as_0_is_said_so_not_called_unstated():
    scan = spec_scan(30.0, calibrated=False)
    run = spec_run(scan)
    run.config["detector"].update(linearity_rel=0.0, range_gain_rel=0.0)
    run.config["optics"]["aperture_diameter_tolerance_mm"] = 0.0
    readings, _ = scan.draw(0)
    data = reduce_readings(run, readings, None, optics_of(run.config, None, run.plan))
    assert not {"linearity", "range_gain", "solid_angle"} & set(data.components)
    notes = [n for n in data.meta["budget"]["notes"] if not n.startswith("angle")]
    assert notes == [
        "linearity: stated as 0 (the config's [detector] linearity_rel)",
        "range_gain: stated as 0 (the config's [detector] range_gain_rel)",
        "solid_angle: stated as 0 (the config's [optics] aperture_diameter_tolerance_mm: +-0, "
        "/ sqrt(3) mm on the diameter)"]


def test_an_unstated_aperture_tolerance_is_iso_2768_fine_and_says_where_the_table_ends():
    from calibration.type_b import solid_angle_figure, tolerance_class_mm

    # ISO 2768-1 table 1, class f: 0.5-6 mm +-0.05, over 6-30 mm +-0.1, over 30-120 mm +-0.15
    assert [tolerance_class_mm(d) for d in (0.5, 6.0, 6.5, 30.0, 31.0, 120.0)] == [
        0.05, 0.05, 0.1, 0.1, 0.15, 0.15]
    optics = dict(wavelength_nm=632.8, bandwidth_nm=0.002, beam_diameter_mm=1.0,
                  divergence_deg=0.0, aperture_distance_mm=500.0, source_polarisation="unpolarised",
                  analyser_polarisation="unpolarised")
    inside = solid_angle_figure(Optics(aperture_diameter_mm=3.5, **optics)).source
    pinhole = solid_angle_figure(Optics(aperture_diameter_mm=0.3, **optics)).source
    assert "ISO 2768-1 table 1" in inside and "outside the table" not in inside
    assert "outside the table's 0.5-2000 mm" in pinhole


def test_each_kind_declares_its_figures_and_a_register_map_may_state_its_own(tmp_path):
    from gonio.device_kinds import KINDS, device_spec

    assert KINDS["pm100"].spec({}) == PM100 and KINDS["zaber"].spec({}) == ZABER
    assert ZABER.repeatability_deg.sigma == pytest.approx(0.02 / math.sqrt(3))
    maps = EXAMPLE.parent.parent / "registermaps"
    config = {"devices": {"amp": {"protocol": "modbus-detector",
                                  "register_map": str(maps / "photodiode-adc.toml")},
                          "drive": {"protocol": "modbus-stage",
                                    "register_map": str(tmp_path / "gone.toml")}}}
    amp = device_spec(config, "amp")
    assert amp.range_gain_rel.sigma == pytest.approx(0.0025 / math.sqrt(3))
    assert "photodiode-adc.toml [specification]" in amp.linearity_rel.source
    drive = device_spec(config, "drive")  # no map to read: the stated conservative default
    assert drive.repeatability_deg.sigma == pytest.approx(0.05 / math.sqrt(3))
    assert "conservative default" in drive.repeatability_deg.source
    assert "unreadable" in drive.repeatability_deg.source
    assert device_spec(config, "nothing") == device_spec({}, "amp")


def test_a_range_gain_cancels_where_the_beam_was_read_on_the_same_range():
    columns = range_columns(np.array([1e-6, 1e-2, 1e-4]), np.array([1e-2, 1e-2]))
    assert columns.shape == (3, 3)
    np.testing.assert_array_equal(np.abs(columns).sum(axis=1), [2.0, 0.0, 2.0])


def test_a_slope_fit_that_does_not_describe_the_data_is_noted_not_refused():
    """The angle terms' slope from a GGX fit of Beckmann data (chi2/dof far above 3): the
    reduction goes on, its budget saying the model does not describe the data; the
    Beckmann fit adds no such note."""
    from calibration.pipeline import reduce_stored

    scan = spec_scan(30.0, calibrated=False)
    readings, _ = scan.draw(0)
    notes = {}
    for distribution in ("ggx", "beckmann"):
        data = reduce_stored(spec_run(scan), readings,
                             slope_options=FitOptions(distributions=(distribution,)))
        budget = data.meta["budget"]
        notes[distribution] = [n for n in budget["notes"] if n.startswith("angle: the slope")]
        assert "angle_repeatability" in data.components
    chi2 = data.meta["budget"]["slope"]["chi2_dof"]
    assert chi2 < 3.0
    assert len(notes["ggx"]) == 1 and not notes["beckmann"]
    assert notes["ggx"][0].startswith("angle: the slope fit (ggx) has chi2/dof ")
    assert notes["ggx"][0].endswith(" > 3: the angle terms come from a model that does not "
                                    "describe the data")


def test_a_plot_of_values_without_the_angle_terms_says_so_in_its_title():
    from calibration.pipeline import reduce_stored
    from calibration.plot import plot_title

    scan = spec_scan(30.0, calibrated=False)
    readings, _ = scan.draw(0)
    titles = [plot_title("run", reduce_stored(spec_run(scan), readings,
                                              slope_options=DEFAULT_SLOPE_FIT,
                                              angle_terms=terms).meta)
              for terms in (False, True)]
    assert titles[0].splitlines()[-1] == ("U excludes the angle terms (--no-angle-terms): the "
                                          "stages' repeatability and angle offsets")
    assert "angle terms" not in titles[1]


def test_a_calibrated_range_gain_counts_the_beams_range_too():
    """A calibration whose reference range is not the beam's: every value is a ratio to the
    beam readings, so the beam range's gain error enters each value read on another range
    (sigma_g / g of both, in quadrature; the reference range's is 0) and cancels on the
    beam's own range."""
    readings, _ = SCAN.draw(0)
    cal = SCAN.calibration()
    cal = dataclasses.replace(cal, gain_reference="1e-05",
                              gains={**cal.gains, "0.01": Measured(1.0, 2e-3),
                                     "1e-05": Measured(1.0, 0.0)})
    data = reduce_readings(run_of(SCAN), readings, cal, SCAN.optics())
    sample = readings[readings["kind"] == "sample"]
    assert set(readings["range_w"][readings["kind"] == "beam"]) == {1e-2}
    rel = np.array([0.0 if r == 1e-5 else SCAN.gain_sigma for r in sample["range_w"]])
    expected = np.where(sample["range_w"] == 1e-2, 0.0, np.hypot(rel, 2e-3))
    assert 1e-5 in set(sample["range_w"]) and len(set(sample["range_w"])) > 2
    np.testing.assert_allclose(data.components["range_gain"],
                               np.abs(data.bsdf) * expected, rtol=1e-12)


def test_coverage_of_U_at_the_declared_specifications_quick():
    """20 seeds per case of docs/fitting.md's coverage table: each case's mean share within
    95 % +- 1.5 % widened by 3 errors of a 20-seed mean (SEED_SCATTER / sqrt(20): 1.9 %
    calibrated, 3.5 % uncalibrated, so >= 0.878 and >= 0.831), and the pooled 80 seeds' by 3 of
    theirs (sqrt(mean of the squared scatters) / sqrt(80) = 1.4 %: >= 0.893; the top bound
    0.995, as 0.965 + 4.2 % is above 1)."""
    shares = coverage(range(20))
    for case, share in shares.items():
        error = SEED_SCATTER[case[1]] / math.sqrt(len(share))
        assert share.mean() >= COVERAGE_BAND[0] - 3.0 * error, (case, share.mean())
    pooled = np.concatenate(list(shares.values()))
    error = math.sqrt(np.mean([SEED_SCATTER[c[1]] ** 2 for c in shares])) / math.sqrt(
        len(pooled))
    assert COVERAGE_BAND[0] - 3.0 * error <= pooled.mean() <= 0.995, pooled.mean()


@pytest.mark.slow
@pytest.mark.timeout(900)  # 4000 scans: ~4 min at load 4 on 2 cores
def test_coverage_of_U_at_the_declared_specifications():
    """Each case within 95 % +- 1.5 % (docs/fitting.md's table: 3000 seeds): 500 seeds per
    calibrated case and 1500 per uncalibrated one (~4 min), so that each mean's error
    (SEED_SCATTER / sqrt(seeds): 0.38 % and 0.40 %) is a quarter of the band's half-width."""
    for calibrated, seeds in ((True, 500), (False, 1500)):
        cases = [case for case in CASES if case[1] == calibrated]
        for case, share in coverage(range(seeds), cases).items():
            assert COVERAGE_BAND[0] <= share.mean() <= COVERAGE_BAND[1], (case, share.mean())


@pytest.fixture(scope="module")
def dark_limited_run(tmp_path_factory):
    """A run on the emulated stack whose sample readings are all below the dark limit (a
    nanowatt source on Walter's ground glass, far from the lobes) and whose stages scatter as
    its config says: no fit, so no slope for their angle terms."""
    tmp = tmp_path_factory.mktemp("dark-limited")
    cfg = instrument(tmp, {"source": {"power_w": 1e-9},
                           "sample": {"multiple_scattering": False},
                           "alignment": {"sample_repeatability_deg": REPEATABILITY_DEG}})
    grids = [{"side": "reflection", "theta_i_deg": 30.0,
              "theta_o_deg": {"start": -70.0, "stop": -40.0, "step": 10.0}}]
    return scan(plan(tmp, "dark", grids, dark_every=4, beam_every=4), cfg, tmp / "runs")


def test_angle_terms_that_cannot_be_estimated_refuse_unless_excluded(dark_limited_run, capsys):
    from calibration.pipeline import reduce_run
    from gonio_cli.main import main

    with pytest.raises(CalibrationError) as err:
        reduce_run(dark_limited_run)
    assert "angle terms" in str(err.value) and "--no-angle-terms" in str(err.value)
    assert "\n" not in str(err.value)
    assert main(["reduce", str(dark_limited_run)]) == 2
    assert "--no-angle-terms" in capsys.readouterr().err
    assert main(["reduce", str(dark_limited_run), "--no-angle-terms"]) == 0
    captured = capsys.readouterr()
    assert "U excludes the budget's angle terms" in captured.err
    assert "angle: excluded (--no-angle-terms)" in captured.out
    header = [ln for ln in (dark_limited_run / "reduced.csv").read_text().splitlines()
              if ln.startswith("# budget: ")]
    assert len(header) == 1 and '"angle_terms": "excluded"' in header[0]
    # the live view (no slope fit) reduces as it goes, without them and without refusing
    live = reduce_run(dark_limited_run, slope_options=None)
    assert "angle_repeatability" not in live.components
