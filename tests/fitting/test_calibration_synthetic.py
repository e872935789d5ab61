"""Calibration from synthetic raw readings with known dark offsets, gains, drift, angle offsets
and aperture: each recovered within its uncertainty; files round-trip; bad files are named."""

import functools
import json
import math

import numpy as np
import pytest

from calibration import aperture, calfile, detector
from calibration.angles import PeakScan, fit_offsets, symmetric_estimate
from calibration.beam import beam_power
from calibration.calibrate import angle_offsets, beam_normalised, build
from calibration.values import CalibrationError, Measured
from gonio.geometry import sample_angles
from gonio.store import READING_DTYPE

RANGES = (1e-7, 1e-6, 1e-5)
DARKS = {1e-7: 3.1e-10, 1e-6: -2.2e-9, 1e-5: 1.4e-8}
GAINS = {1e-7: 1.031, 1e-6: 0.987, 1e-5: 1.0}


def readings(n: int, **fields) -> np.ndarray:
    out = np.zeros(n, READING_DTYPE)
    out["index"] = np.arange(n)
    for name, value in fields.items():
        out[name] = value
    return out


def detector_runs(rng: np.random.Generator, exponent: float = 1.0) -> np.ndarray:
    """The calib-detector plan run once per fixed range: 8 darks and 12 points x 8 repeats;
    `exponent` makes the 1e-6 W range read P^exponent (a non-linear amplifier stage)."""
    powers = np.geomspace(2e-9, 8e-6, 12)
    runs = []
    for r in RANGES:
        noise = 2e-4 * r
        dark = readings(8, kind="dark", range_w=r, point=-1,
                        power_w=DARKS[r] + noise * rng.standard_normal(8))
        point = np.repeat(np.arange(12), 8)
        true = powers[point]
        gamma = exponent if r == 1e-6 else 1.0  # a range-dependent non-linearity
        m = GAINS[r] * true * (true / 1e-7) ** (gamma - 1.0) + DARKS[r]
        m = m + noise * rng.standard_normal(len(m)) + 1e-3 * m * rng.standard_normal(len(m))
        sample = readings(len(m), kind="sample", side="reflection", range_w=r, point=point,
                          arm_deg=20.0 + 5.0 * point, power_w=np.minimum(m, 1.1 * r),
                          saturated=m > 1.1 * r)
        runs += [dark, sample]
    return np.concatenate(runs)


def test_dark_offsets_and_gains_recovered_within_uncertainty():
    data = detector_runs(np.random.default_rng(1))
    darks = detector.dark_offsets(data)
    for r, truth in DARKS.items():
        assert abs(darks[detector.range_key(r)].pull(truth)) < 3.0
    gains = detector.gain_ratios(data, darks)
    assert gains.reference == detector.range_key(1e-5)
    for r, truth in GAINS.items():
        g = gains.gains[detector.range_key(r)]
        assert abs(g.value - truth) < 3.0 * g.sigma + 1e-12
        assert g.sigma < 0.01
    assert 0.3 < gains.chi2_dof < 3.0  # sigmas are estimated from 8 repeats per cell
    for gamma in gains.exponents.values():
        assert abs(gamma.pull(1.0)) < 3.0


def test_nonlinear_detector_is_flagged_by_the_linearity_check():
    data = detector_runs(np.random.default_rng(2), exponent=1.02)
    gains = detector.gain_ratios(data, detector.dark_offsets(data))
    # both signs of non-linearity: the joint gain model fits badly, and the 1e-6 W range's
    # power-law exponent against the reference range departs from 1
    assert gains.chi2_dof > 3.0
    assert abs(gains.exponents["1e-06"].pull(1.0)) > 3.0
    # and building a calibration from it warns of the bad fit, which a linear detector's does not
    warned = [n for n in build([data], "", ["run"]).notes if n.startswith("gains: warning")]
    assert warned == [f"gains: warning: the gain fit has chi2/dof {gains.chi2_dof:.3g} > 3: "
                      "the model misses the readings by more than their noise (its sigmas are "
                      "scaled by sqrt(chi2/dof), but its values may be biased)"]
    linear = build([detector_runs(np.random.default_rng(2))], "", ["run"])
    assert not [n for n in linear.notes if "warning" in n]


@pytest.mark.parametrize("seed", range(4))
def test_pooled_noise_law_holds_the_meters_read_and_shot_noise(seed):
    # Powers from 1e-10 W to 0.8 mW autoranged, as across a peak scan, three repeats of four
    # averaged samples each on the emulated meter: its noise is read noise in proportion to the
    # range, shot noise in proportion to the signal (dominant in the lowest range's upper part)
    # and quantisation. The law pooled from the repeats gives every point's error within
    # 25 % of what the meter's physics predicts.
    from sim.devices.photodiode import PhotodiodeModel

    meter = PhotodiodeModel(seed=seed)
    meter.zero(632.8)
    groups, full_scale, truth = [], [], []
    for k, power in enumerate(np.geomspace(1e-10, 8e-4, 90)):
        range_w = meter.autorange(power, 632.8)
        groups.append(np.array([meter.measure(power, range_w, 4, 632.8, (k,)).reading_w
                                for _ in range(3)]))
        full_scale.append(range_w)
        truth.append(meter.expected_sigma_w(power, range_w, 4, 632.8) / math.sqrt(3))
    ratio = detector.pooled_sem(groups, np.array(full_scale)) / np.array(truth)
    assert 0.75 < ratio.min() and ratio.max() < 1.4, (ratio.min(), ratio.max())


def test_one_range_only_gives_a_clear_error():
    data = detector_runs(np.random.default_rng(3))
    data = data[data["range_w"] == 1e-6]
    with pytest.raises(CalibrationError, match="at least two ranges"):
        detector.gain_ratios(data, detector.dark_offsets(data))


ANGLE_BENCH = {  # an anti-glare reference on its hemisphere, 10 mm aperture at 500 mm
    "source": {"power_w": 1.0, "beam_diameter_mm": 2.0, "divergence_deg": 0.03},
    "sample": {"kind": "hemisphere", "distribution": "beckmann", "alpha": 0.023, "eta": 1.51,
               "multiple_scattering": False},
    "aperture": {"diameter_mm": 10.0, "distance_mm": 500.0, "rtol": 1e-5},
}
HALF_ANGLE_DEG = math.degrees(math.atan(5.0 / 500.0))


@functools.cache
def peak_scan_power(ds: float, da: float) -> list[tuple[str, float, np.ndarray, np.ndarray]]:
    """(side, reported sample, reported arm, true power) of the calib-angles scans (transmitted
    peak at sample 0, specular at 10 deg) on sim.bench's bench misaligned by (ds, da): the
    bench's own aperture integral, an implementation independent of calibration's model."""
    from sim.bench.config import build_bench

    bench = build_bench({**ANGLE_BENCH, "alignment": {"sample_offset_deg": ds,
                                                      "arm_offset_deg": da}})
    scans = [("transmission", 0.0, 180.0 + np.arange(-2.5, 2.51, 0.25)),
             ("reflection", 10.0, np.arange(12.0, 28.01, 0.5))]
    return [(side, s, arm, np.array([bench.power_w({"sample": s, "arm": a}) for a in arm]))
            for side, s, arm in scans]


def peak_scan_readings(rng, ds: float, da: float, repeats: int = 3) -> np.ndarray:
    """Repeated readings of the peak scans: relative noise 3e-4 and a read-noise floor."""
    blocks, point = [], 0
    for side, s, arm, power in peak_scan_power(ds, da):
        for a, p in zip(arm, power, strict=True):
            m = p * (1 + 3e-4 * rng.standard_normal(repeats)) + 1e-9 * rng.standard_normal(repeats)
            blocks.append(readings(repeats, kind="sample", side=side, point=point, sample_deg=s,
                                   arm_deg=a, power_w=m, range_w=1.0))
            point += 1
    return np.concatenate(blocks)


def test_angle_offsets_recovered_within_uncertainty():
    rng = np.random.default_rng(4)
    ds_true, da_true = 0.3, -0.2
    fit = angle_offsets(peak_scan_readings(rng, ds_true, da_true), 1.51, HALF_ANGLE_DEG, 0.03)
    assert abs(fit.sample_offset.pull(ds_true)) < 3.0 and abs(fit.arm_offset.pull(da_true)) < 3.0
    assert 0 < fit.sample_offset.sigma < 2e-4 and 0 < fit.arm_offset.sigma < 2e-4
    assert fit.distribution == "beckmann" and abs(fit.alpha.value / 0.023 - 1) < 1e-3
    assert 0.3 < fit.chi2_dof < 2.0


def test_an_aperture_known_to_its_error_is_fitted_within_it_and_the_offsets_stay_right():
    """A beam scan's aperture (0.0003 deg high: its 1.2 sigma, as one measured on the emulated
    bench) taken as exact misfits the anti-glare peaks at chi2/dof ~ 60; fitted within that
    prior the peaks fit at ~1, the half-angle comes back to the bench's, the offsets right."""
    rng = np.random.default_rng(4)
    ds_true, da_true = 0.3, -0.2
    data = peak_scan_readings(rng, ds_true, da_true)
    measured = HALF_ANGLE_DEG + 3.6e-4
    fixed = angle_offsets(data, 1.51, measured, 0.03)
    free = angle_offsets(data, 1.51, measured, 0.03, aperture_sigma_deg=2.9e-4)
    assert fixed.chi2_dof > 10.0 and fixed.aperture_half_angle is None
    assert 0.3 < free.chi2_dof < 2.0
    assert abs(free.aperture_half_angle.pull(HALF_ANGLE_DEG)) < 3.0
    assert free.aperture_half_angle.sigma < 1e-4  # the peaks know it better than the scan
    assert abs(free.sample_offset.pull(ds_true)) < 3.0 and abs(free.arm_offset.pull(da_true)) < 3.0


def test_symmetry_centres_are_biased_and_the_model_fit_is_not():
    # Noise-free peaks: the mirror-symmetry estimate (the former method) is off by 1-2e-4 deg,
    # several sigma of a real run, because a reflected lobe is not symmetric about the specular
    # direction and linear interpolation of a coarse scan skews a symmetry centre; the model
    # fit recovers the offsets to 1e-6 deg.
    ds_true, da_true = 0.3, -0.2
    scans = [PeakScan(side, np.full(len(arm), s), arm, np.zeros(len(arm)), np.zeros(len(arm)),
                      power, 1e-4 * power + 1e-4 * power.max())
             for side, s, arm, power in peak_scan_power(ds_true, da_true)]
    ds_sym, da_sym = symmetric_estimate(scans, 1.51)
    assert max(abs(ds_sym - ds_true), abs(da_sym - da_true)) > 1e-4
    fit = fit_offsets(scans, 1.51, HALF_ANGLE_DEG, 0.03)
    assert abs(fit.sample_offset.value - ds_true) < 1e-6
    assert abs(fit.arm_offset.value - da_true) < 1e-6


def test_offsets_at_zero_get_the_covariance_of_offsets_away_from_it():
    # A bench aligned exactly (both offsets 0, as the emulated bench without [sim.alignment]):
    # the fit's Jacobian steps are absolute, so its covariance there is that of a misaligned
    # bench's (the geometry differs by a few tenths of a degree only), not singular or
    # quantised by the float spacing of the stage angles.
    def noise_free_fit(ds: float, da: float):
        scans = [PeakScan(side, np.full(len(arm), s), arm, np.zeros(len(arm)),
                          np.zeros(len(arm)), power, 1e-4 * power + 1e-4 * power.max())
                 for side, s, arm, power in peak_scan_power(ds, da)]
        return fit_offsets(scans, 1.51, HALF_ANGLE_DEG, 0.03)

    aligned, misaligned = noise_free_fit(0.0, 0.0), noise_free_fit(0.3, -0.2)
    assert abs(aligned.sample_offset.value) < 1e-6 and abs(aligned.arm_offset.value) < 1e-6
    for part in ("sample_offset", "arm_offset"):
        ratio = getattr(aligned, part).sigma / getattr(misaligned, part).sigma
        assert abs(ratio - 1.0) < 0.05, (part, ratio)


def test_angle_calibration_without_repeats_is_refused():
    data = peak_scan_readings(np.random.default_rng(5), 0.3, -0.2, repeats=1)
    with pytest.raises(CalibrationError, match="repeated readings"):
        angle_offsets(data, eta=1.51)


def test_beam_drift_interpolated_within_its_uncertainty():
    rng = np.random.default_rng(6)
    t_beam = np.linspace(0.0, 1800.0, 31)

    def truth(t):
        return 1e-3 * (1.0 + 0.05 * np.sin(2 * np.pi * t / 3600.0))

    measured = truth(t_beam) + 2e-7 * rng.standard_normal(len(t_beam))
    model = beam_power(t_beam, measured)
    t = rng.uniform(0.0, 1800.0, 500)
    power, sigma = model.at(t)
    pulls = (power - truth(t)) / sigma
    assert np.all(np.abs(pulls) < 4.0)
    assert 0.3 < np.sqrt(np.mean(pulls ** 2)) < 1.5
    assert model.noise_w == pytest.approx(2e-7, rel=0.35)
    true_drift = truth(t_beam)
    assert model.drift_rms == pytest.approx(true_drift.std() / true_drift.mean(), rel=0.05)


def test_saturated_beam_readings_do_not_normalise_the_peaks():
    """A beam read on a range at its own power reads over range half the time (clipped at
    1.1 full scale, flagged saturated): those readings are left out of the normalisation, and
    a run whose every beam reading is saturated says so."""
    rng = np.random.default_rng(8)
    t = np.arange(40.0)
    sample = readings(30, kind="sample", side="reflection", point=np.arange(30), t_s=t[10:],
                      power_w=1e-6, range_w=1e-5)
    good = readings(10, kind="beam", t_s=t[:10], range_w=1e-2,
                    power_w=1e-3 * (1.0 + 1e-4 * rng.standard_normal(10)))
    clipped = good.copy()
    clipped["power_w"][::2], clipped["saturated"][::2] = 1.1e-2, True
    darks = {"1e-05": Measured(0.0, 0.0), "0.01": Measured(0.0, 0.0)}
    kept, _ = beam_normalised(np.concatenate([good[1::2], sample]), darks, None)
    both, _ = beam_normalised(np.concatenate([clipped, sample]), darks, None)
    np.testing.assert_allclose(both["power_w"][both["kind"] == "sample"],
                               kept["power_w"][kept["kind"] == "sample"], rtol=1e-12)
    all_clipped = good.copy()
    all_clipped["saturated"] = True
    dark = readings(4, kind="dark", range_w=[1e-5, 1e-5, 1e-2, 1e-2],
                    power_w=1e-9 * rng.standard_normal(4))
    notes = build([np.concatenate([dark, all_clipped, sample])], "", ["RUN"]).notes
    assert [n for n in notes if n.startswith("beam:")] == [
        "beam: every beam reading of RUN is saturated (over range), so none normalises it: "
        "give the plan's [beam] a range above the beam's power"]
    assert not [n for n in build([np.concatenate([dark, clipped, sample])], "", ["RUN"]).notes
                if n.startswith("beam:")]


def overlap_scan_monte_carlo(rng, a: float, b: float, offsets: np.ndarray) -> np.ndarray:
    """Fraction of a uniform beam disk (radius b) inside an aperture disk (radius a) whose centre
    is offset along x: an independent Monte Carlo route to the scan profile."""
    r = b * np.sqrt(rng.uniform(size=40000))
    phi = rng.uniform(0, 2 * np.pi, size=40000)
    x, y = r * np.cos(phi), r * np.sin(phi)
    return np.array([np.mean((x - u) ** 2 + y ** 2 <= a * a) for u in offsets])


@pytest.mark.parametrize("beam_fraction", [0.0, 0.4])
def test_aperture_from_beam_scan_matches_geometry(beam_fraction):
    rng = np.random.default_rng(7)
    radius_m, distance_m = 5e-3, 0.5
    a, b = radius_m / distance_m, beam_fraction * radius_m / distance_m
    arm = 180.0 + np.degrees(np.arange(-1.6 * a, 1.6 * a, a / 40))
    offset = np.tan(np.radians(arm - 180.0))
    profile = (overlap_scan_monte_carlo(rng, a, b, offset) if b > 0
               else (np.abs(offset) <= a).astype(float))
    power = 1e-3 * profile
    sigma = np.full(len(power), 1e-3 * 2e-3)
    omega, half = aperture.from_beam_scan(arm, power, sigma, beam_radius_rad=b)
    expected = aperture.from_geometry(radius_m, distance_m)
    # the sampling step (a/40) limits the width to about a step: the stated sigma covers noise
    assert omega.value == pytest.approx(expected, rel=0.03)
    assert half.value == pytest.approx(math.degrees(math.atan(a)), rel=0.015)


def test_calibration_file_round_trip_and_apply(tmp_path):
    rng = np.random.default_rng(8)
    data = detector_runs(rng)
    runs = [data[data["range_w"] == r] for r in RANGES]  # one fixed-range run per range
    cal = build(runs, "2026-11-23T12:00:00Z", ["runs/a", "runs/b", "runs/c"])
    cal.sample_offset_deg, cal.arm_offset_deg = Measured(0.3, 0.01), Measured(-0.2, 0.01)
    path = calfile.save(cal, tmp_path / "cal.json")
    back = calfile.load(path)
    assert back.to_json() == cal.to_json()
    raw = readings(2, kind="sample", side="reflection", sample_deg=[10.0, 30.0],
                   arm_deg=[20.0, 150.0], range_w=1e-6, power_w=[1e-7, 5e-7])
    out = calfile.apply(raw, back)
    expected = (raw["power_w"] - back.dark_offsets_w["1e-06"].value) / back.gains["1e-06"].value
    np.testing.assert_allclose(out["power_w"], expected)
    np.testing.assert_allclose(out["sample_deg"], [10.3, 30.3])
    angles = sample_angles([10.3, 30.3], [19.8, 149.8])
    np.testing.assert_allclose(out["theta_o_deg"], angles.theta_o_deg)
    meta = {"calibration": calfile.reference(path)}
    assert calfile.used_by(meta).to_json() == cal.to_json()
    path.write_text(path.read_text().replace("2026-11-23", "2026-11-24"))
    with pytest.raises(CalibrationError, match="changed after the run"):
        calfile.used_by(meta)


def test_bad_calibration_file_names_the_field(tmp_path):
    path = tmp_path / "bad.json"
    path.write_text(json.dumps({"format": calfile.FORMAT,
                                "angles": {"arm_offset_deg": {"value": "x", "sigma": 1}}}))
    with pytest.raises(CalibrationError, match=r"bad.json: \[angles\] arm_offset_deg: must be"):
        calfile.load(path)
    path.write_text("{}")
    with pytest.raises(CalibrationError, match="not a gonio calibration file"):
        calfile.load(path)


def test_ranges_without_darks_use_the_nearest_and_missing_gains_are_named():
    darks = {"1e-06": Measured(1.0, 0.0), "1e-03": Measured(5.0, 0.0)}
    out = detector.correct_power(np.array([3.0, 9.0]), np.array([1e-5, 1e-2]), darks, None)
    np.testing.assert_allclose(out, [2.0, 4.0])
    gains = {"1e-06": Measured(1.0, 0.0)}
    with pytest.raises(CalibrationError, match="no gain for range 1e-05"):
        detector.correct_power(np.array([1.0]), np.array([1e-5]), darks, gains)
    autoranged = readings(4, kind="sample", point=[0, 0, 1, 1], arm_deg=[20, 20, 30, 30],
                          range_w=[1e-6, 1e-6, 1e-5, 1e-5])
    assert not detector.ranges_read_together(autoranged)
    assert detector.ranges_read_together(detector_runs(np.random.default_rng(0)))
