"""The detector model: noise statistics, averaging, ranges, saturation, quantisation, errors."""

import numpy as np
import pytest
from scipy import stats

from sim.devices.photodiode import (
    ConstantPower,
    PhotodiodeModel,
    PowerSource,
    SimConfigError,
)

WL = 632.8


def readings(model, power, n, **kw):
    return np.array([model.measure(power, wavelength_nm=WL, **kw).reading_w for _ in range(n)])


@pytest.mark.parametrize("averaging", [1, 16])
def test_mean_and_std_match_the_noise_model(averaging):
    model = PhotodiodeModel({"read_noise_fraction": 1e-3, "dark_current_a": 0.0}, seed=3)
    power, range_w = 3.0e-6, 1e-5
    x = readings(model, power, 2000, range_w=range_w, averaging=averaging)
    sigma = model.expected_sigma_w(power, range_w, averaging, WL)
    # mean within 4 standard errors, variance by a chi-square interval
    assert abs(x.mean() - power) < 4 * sigma / np.sqrt(len(x))
    dof = len(x) - 1
    chi2 = dof * x.var(ddof=1) / sigma**2
    assert stats.chi2.ppf(0.0005, dof) < chi2 < stats.chi2.ppf(0.9995, dof)
    # a Gaussian shape: Kolmogorov-Smirnov against N(power, sigma)
    assert stats.kstest((x - power) / sigma, "norm").pvalue > 1e-3


def test_noise_falls_as_one_over_sqrt_averaging():
    model = PhotodiodeModel({"read_noise_fraction": 1e-3}, seed=5)
    s1 = readings(model, 5e-6, 1500, range_w=1e-5, averaging=1).std()
    s64 = readings(model, 5e-6, 1500, range_w=1e-5, averaging=64).std()
    assert s1 / s64 == pytest.approx(8.0, rel=0.1)


def test_shot_noise_dominates_without_read_noise_and_scales_as_sqrt_power():
    cfg = {"read_noise_fraction": 0.0, "dark_current_a": 0.0, "bandwidth_hz": 1e9,
           "adc_bits": 32}
    model = PhotodiodeModel(cfg, seed=7)
    q, r = 1.602176634e-19, model.responsivity_a_w(WL)
    for power in (1e-8, 1e-6):
        expected = np.sqrt(2 * q * r * power * 1e9) / r
        assert model.expected_sigma_w(power, model.range_for(power), 1, WL) == pytest.approx(
            expected, rel=1e-6)
        x = readings(model, power, 1500, range_w=model.range_for(power / 0.5))
        assert x.std(ddof=1) == pytest.approx(expected, rel=0.08)


def test_dark_offset_stray_light_and_zero():
    model = PhotodiodeModel({"dark_current_a": 1e-9, "stray_light_w": 2e-9,
                             "read_noise_fraction": 1e-5}, seed=1)
    offset = 1e-9 / model.responsivity_a_w(WL) + 2e-9
    assert readings(model, 0.0, 200, range_w=1e-8).mean() == pytest.approx(offset, rel=0.01)
    model.zero(WL)
    assert abs(readings(model, 0.0, 200, range_w=1e-8).mean()) < 1e-11


def test_wavelength_correction_mismatch_scales_the_reading():
    model = PhotodiodeModel({"read_noise_fraction": 1e-6, "dark_current_a": 0.0}, seed=1,
                            light_wavelength_nm=800.0)
    got = model.measure(5e-4, 1e-3, 1, WL).reading_w
    ratio = model.responsivity_a_w(800.0) / model.responsivity_a_w(WL)
    assert got == pytest.approx(5e-4 * ratio, rel=1e-4)
    assert ratio > 1.2  # silicon is more responsive in the near infrared


def test_autorange_picks_the_smallest_range_that_holds_the_signal():
    model = PhotodiodeModel(seed=0)
    assert model.measure(5e-7, None, 1, WL).range_w == 1e-6
    assert model.measure(9.5e-7, None, 1, WL).range_w == 1e-5  # above 90 % fill
    assert model.measure(0.0, None, 1, WL).range_w == 1e-8


def test_saturation_flag_and_clipping():
    model = PhotodiodeModel(seed=0)
    m = model.measure(5e-6, 1e-6, 4, WL)
    assert m.saturated and m.reading_w == pytest.approx(1.1e-6, rel=1e-4)
    top = model.measure(1.0, None, 1, WL)
    assert top.saturated and top.range_w == 1e-2
    assert not model.measure(5e-7, 1e-6, 4, WL).saturated


def test_quantisation_step_per_range():
    model = PhotodiodeModel({"read_noise_fraction": 0.0, "dark_current_a": 0.0,
                             "bandwidth_hz": 0.0, "adc_bits": 8}, seed=0)
    step = model.adc_step_w(1e-6)
    assert step == pytest.approx(2 * 1.1e-6 / 256)
    value = model.measure(3.3e-7, 1e-6, 1, WL).reading_w
    assert value / step == pytest.approx(round(3.3e-7 / step), abs=1e-9)


def test_range_gain_errors_scale_the_reading_on_their_range_only():
    # reading = gain x (P + dark) / R' - zero: a range's gain error multiplies its readings
    gains = [1.0, 1.0, 1.0, 1.0, 1.02, 0.97, 1.0]
    model = PhotodiodeModel({"range_gains": gains, "dark_current_a": 0.0}, seed=5)
    ideal = PhotodiodeModel({"dark_current_a": 0.0}, seed=5)
    for range_w, gain in [(1e-4, 1.02), (1e-3, 0.97), (1e-2, 1.0)]:
        x = readings(model, 5e-5, 400, range_w=range_w)
        y = readings(ideal, 5e-5, 400, range_w=range_w)
        sigma = model.expected_sigma_w(5e-5, range_w, 1, WL) / np.sqrt(400)
        assert abs(x.mean() - gain * 5e-5) < 4 * sigma
        assert abs(y.mean() - 5e-5) < 4 * sigma
    assert model.gain(1e-4) == 1.02 and ideal.gain(1e-4) == 1.0
    # autoranging judges the reading (gain x power) against autorange_fill x full scale
    assert model.autorange(0.9e-4 / 1.02 * 0.99, WL) == 1e-4
    assert model.autorange(0.9e-4 / 1.02 * 1.01, WL) == 1e-3


def test_seeded_draws_repeat():
    a = readings(PhotodiodeModel(seed=11), 1e-6, 5, range_w=1e-5)
    b = readings(PhotodiodeModel(seed=11), 1e-6, 5, range_w=1e-5)
    assert np.array_equal(a, b)


def test_noise_is_keyed_on_place_range_and_visit_not_on_call_order():
    here, there = (10.0, 150.0, 0.0, 0.0), (20.0, 140.0, 0.0, 0.0)

    def reading(model, place, range_w=1e-5):
        return model.measure(1e-6, range_w, 4, WL, place=place).reading_w

    first = PhotodiodeModel(seed=4)
    taken = [reading(first, here), reading(first, there), reading(first, here)]
    assert len(set(taken)) == 3  # every visit draws afresh
    resumed = PhotodiodeModel(seed=4)  # a resumed run: one reading at `here` is stored
    resumed.visited(here, 1e-5)
    assert [reading(resumed, here), reading(resumed, there)] == [taken[2], taken[1]]
    assert reading(PhotodiodeModel(seed=4), there, None) != taken[1]  # autorange: another key
    assert reading(PhotodiodeModel(seed=5), here) != taken[0]  # another device or seed


def test_constant_power_is_a_power_source():
    src = ConstantPower(2e-6)
    assert isinstance(src, PowerSource) and src.power_w() == 2e-6
    with pytest.raises(ValueError, match="power_w"):
        ConstantPower(-1.0)


@pytest.mark.parametrize(
    "table, field",
    [
        ({"ranges_w": [1e-3, 1e-4]}, "ranges_w"),
        ({"adc_bits": 2.5}, "adc_bits"),
        ({"dark_current_a": -1}, "dark_current_a"),
        ({"responsivity": [[500, 0.3]]}, "responsivity"),
        ({"gain": 3}, "gain"),
        ({"overrange": "x"}, "overrange"),
        ({"range_gains": [1.0, 1.01]}, "range_gains"),  # one per range (7 by default)
        ({"range_gains": [1.0] * 6 + [3.0]}, "range_gains"),
        ({"range_gains": "x"}, "range_gains"),
    ],
)
def test_bad_config_names_the_field(table, field):
    with pytest.raises(SimConfigError, match=field):
        PhotodiodeModel(table)


def test_bad_measure_arguments():
    model = PhotodiodeModel()
    with pytest.raises(ValueError, match="range_w"):
        model.measure(1e-6, 3e-6, 1, WL)
    with pytest.raises(ValueError, match="averaging"):
        model.measure(1e-6, None, 0, WL)
    with pytest.raises(ValueError, match="power_w"):
        model.measure(float("nan"), None, 1, WL)
