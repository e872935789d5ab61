"""calibration.signature on synthetic readings: interpolation in arm angle with its sigma, the
share flag, what subtraction does to the net signal and its noise, coverage per elevation, and
the errors."""

import numpy as np
import pytest

from calibration.beam import beam_power
from calibration.dark import DarkModel
from calibration.reduced import ReducedData
from calibration.signature import apply_signature, interpolate, summary
from calibration.values import CalibrationError
from gonio.store import READING_DTYPE

RANGE = 1e-8
LEVEL, NOISE = 1e-10, 1e-12
DARK = DarkModel({RANGE: LEVEL}, {RANGE: 0.0}, {RANGE: NOISE})
PHI = 1e-3
BEAM = beam_power(np.array([0.0, 100.0]), np.array([PHI, PHI]), 1e-9)


def readings(kind, arm, power, elevation=0.0):
    out = np.zeros(len(arm), READING_DTYPE)
    out["kind"], out["arm_deg"], out["elevation_deg"] = kind, arm, elevation
    out["power_w"], out["range_w"], out["t_s"] = power, RANGE, 50.0
    return out


def test_interpolation_is_linear_between_arm_positions_with_its_sigma():
    arm = np.array([170.0, 172.0, 172.0, 176.0])
    value = np.array([1.0, 3.0, 5.0, 8.0])
    sigma = np.array([0.1, 0.2, 0.2, 0.4])
    at = np.array([170.0, 171.0, 172.0, 174.0, 169.0, 177.0])
    got, got_sigma = interpolate(arm, value, sigma, at)
    mean_172, sigma_172 = 4.0, 0.2 / np.sqrt(2.0)  # the two readings at 172 averaged
    np.testing.assert_allclose(got[:4], [1.0, 0.5 * (1.0 + mean_172), mean_172,
                                         0.5 * (mean_172 + 8.0)])
    np.testing.assert_allclose(got_sigma[:4], [0.1, np.hypot(0.05, 0.5 * sigma_172),
                                               sigma_172, np.hypot(0.5 * sigma_172, 0.2)])
    assert np.isnan(got[4:]).all() and np.isnan(got_sigma[4:]).all()  # never extrapolated
    one, one_sigma = interpolate(arm[:1], value[:1], sigma[:1], np.array([170.0, 171.0]))
    assert one[0] == 1.0 and one_sigma[0] == 0.1 and np.isnan(one[1])


def reduce_like(signature_power, sample_power, share=0.1, subtract=False, elevation=0.0):
    arm = np.array([170.0, 175.0, 180.0, 185.0])
    sig = readings("signature", arm, LEVEL + signature_power)
    rows = readings("sample", np.array([170.0, 172.5, 185.0, 190.0]), sample_power,
                    elevation)
    net = rows["power_w"] - LEVEL
    noise = np.full(len(rows), NOISE)
    scale = np.full(len(rows), 1e-6)
    return apply_signature(np.concatenate([sig, rows]), rows, DARK, BEAM, 0.0, net, noise,
                           scale, share, subtract), net


def test_flags_subtraction_and_coverage():
    sig_power = np.array([1e-11, 2e-11, 3e-11, 4e-11])
    sample = LEVEL + np.array([1e-9, 1e-10, 1e-10, 1e-10])
    plain, net = reduce_like(sig_power, sample)
    # at 172.5 the signature interpolates to 1.5e-11 (15 % of 1e-10), at 185 4e-11 (40 %);
    # 190 lies outside the signature's arm span
    assert list(plain.flags) == ["", "signature", "signature", ""]
    assert list(plain.invalid) == [False, True, True, False] and plain.invalid.dtype == bool
    np.testing.assert_array_equal(plain.net_w, net)  # not subtracted
    meta = plain.meta
    assert (meta["flagged"], meta["uncovered"], meta["readings"]) == (2, 1, 4)
    np.testing.assert_allclose(meta["bsdf_per_sr"][:3], [1e-5, 1.5e-5, 4e-5])
    assert meta["bsdf_per_sr"][3] is None
    np.testing.assert_allclose(meta["dark_floor_per_sr"], NOISE / 1e-6)
    assert meta["ranges"]["1e-08"]["points"] == 4

    sub, _ = reduce_like(sig_power, sample, subtract=True)
    assert not sub.invalid.any() and sub.invalid.dtype == bool
    assert list(sub.flags) == list(plain.flags)
    np.testing.assert_allclose(sub.net_w, net - [1e-11, 1.5e-11, 4e-11, 0.0], rtol=1e-9)
    # the signature's own noise (one reading, interpolated) joins the sample's
    np.testing.assert_allclose(sub.noise_w, [np.sqrt(2.0) * NOISE,
                                             np.hypot(NOISE, np.sqrt(0.5) * NOISE),
                                             np.sqrt(2.0) * NOISE, NOISE], rtol=1e-9)
    assert sub.meta["subtracted"] and "subtracted" in summary(sub.meta)[0]
    assert "left out" in summary(meta)[0] and "outside its arm span" in summary(meta)[0]

    loose, _ = reduce_like(sig_power, sample, share=0.5)
    assert not loose.invalid.any()
    other_plane, _ = reduce_like(sig_power, sample, elevation=5.0)  # no signature there
    assert other_plane.meta["uncovered"] == 4 and not other_plane.invalid.any()


def test_errors_and_a_run_without_signature_readings():
    rows = readings("sample", np.array([170.0]), np.array([2e-10]))
    args = (rows, rows, DARK, BEAM, 0.0, rows["power_w"] - LEVEL, np.full(1, NOISE),
            np.ones(1))
    none = apply_signature(*args)
    assert none.meta is None and list(none.flags) == [""] and not none.invalid.any()
    with pytest.raises(CalibrationError, match="no unsaturated signature readings"):
        apply_signature(*args, subtract=True)
    with pytest.raises(CalibrationError, match=r"share must be in \(0, 1\)"):
        apply_signature(*args, share=1.5)


def test_reduced_data_keeps_its_flags_in_a_subset():
    n = 3
    data = ReducedData(np.tile([0.0, 0.0, 1.0], (n, 1)), np.tile([0.0, 0.0, 1.0], (n, 1)),
                       np.ones(n), np.ones(n), np.ones(n, bool), np.zeros(n, bool),
                       flags=np.array(["", "signature", ""]))
    assert list(data.subset(np.array([1, 2])).flags) == ["signature", ""]
    assert list(ReducedData(data.wi, data.wo, data.bsdf, data.sigma, data.valid,
                            data.transmission).flags) == ["", "", ""]
