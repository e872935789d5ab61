"""The beam normalisation and the errors it shares between points: the beam curve follows a
drift too slow to detect (the Walter examples' 1 % source over a 20 s run), its shared errors
have the covariance they claim, the fit and the held-out score take them as a covariance, and
reduction's noise law holds the signal's shot noise as the emulated meter makes it."""

import math

import numpy as np
import pytest

from calibration.beam import beam_power
from calibration.fit import FitOptions, fit
from calibration.reduced import ReducedData
from calibration.synthetic import synthesize
from sim.devices.photodiode import PhotodiodeModel
from sim.truth import emulator_shot_noise_w

N_BEAM, SPAN_S, NOISE_REL = 28, 20.0, 5e-4  # as in a Walter example run on the emulated bench


def true_beam(t: np.ndarray) -> np.ndarray:
    """1 mW drifting 1 % with a 1800 s period: 7e-4 over the run, below what 28 readings with
    5e-4 noise can tell from a constant (chi-square p ~ 0.1-0.4 in the example runs)."""
    return 1e-3 * (1.0 + 0.01 * np.sin(2.0 * np.pi * t / 1800.0))


def beam_pulls(seeds: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Over seeds: (pulls at sample times, errors at three times, their predicted covariance)."""
    t_beam = np.linspace(0.0, SPAN_S, N_BEAM)
    t = np.linspace(0.0, SPAN_S, 41)
    pulls, errors, predicted = [], [], []
    for seed in range(seeds):
        rng = np.random.default_rng(seed)
        p = true_beam(t_beam) * (1.0 + NOISE_REL * rng.standard_normal(N_BEAM))
        power, sigma, shared = beam_power(t_beam, p, 1e-3 * NOISE_REL).smooth(t)
        pulls.append((power - true_beam(t)) / sigma)
        ends = [0, 20, 40]
        errors.append(power[ends] - true_beam(t[ends]))
        predicted.append(shared[ends] @ shared[ends].T)
    return np.array(pulls), np.array(errors), np.mean(predicted, axis=0)


def test_beam_curve_follows_a_drift_below_detection():
    pulls, _, _ = beam_pulls(300)
    # the mean of the readings would be off by +-3.5e-4 at the run's ends with a sigma of
    # 0.95e-4 (pulls -3.7 and +3.7); the curve is unbiased there
    for where in (slice(0, 4), slice(18, 23), slice(37, 41)):
        assert abs(pulls[:, where].mean()) < 0.25, where
    assert 0.85 < np.sqrt(np.mean(pulls**2)) < 1.2


def test_beam_curve_errors_have_the_covariance_they_claim():
    _, errors, predicted = beam_pulls(400)
    measured = np.cov(errors.T)
    scale = np.sqrt(np.outer(np.diag(predicted), np.diag(predicted)))
    # start, middle and end of the run: variances and correlations (the start and the end of
    # a straight line anti-correlate) within the sampling error of 400 runs
    assert np.allclose(measured / scale, predicted / scale, atol=0.15)
    assert measured[0, 2] < 0 and predicted[0, 2] < 0


def test_fewer_than_four_beam_readings_interpolate_with_their_shared_errors():
    model = beam_power(np.array([0.0, 10.0, 20.0]), np.array([1.0, 1.1, 1.0]), 0.01)
    power, sigma, shared = model.smooth(np.array([0.0, 5.0, 25.0]))
    assert np.allclose(power, [1.0, 1.05, 1.0])
    assert np.allclose(shared, 0.01 * np.array([[1, 0, 0], [0.5, 0.5, 0], [0, 0, 1]]))
    assert np.all(sigma >= np.linalg.norm(shared, axis=1))


def shared_data(rng: np.random.Generator, n: int, k: int) -> tuple[ReducedData, np.ndarray]:
    """Random data with k shared relative errors; returns it and its own (independent) sigma."""
    model = rng.uniform(0.5, 2.0, n)
    own = rng.uniform(0.01, 0.05, n)
    shared_rel = rng.normal(0.0, 0.01, (n, k))
    bsdf = model * (1.0 + shared_rel @ rng.standard_normal(k)) + own * rng.standard_normal(n)
    sigma = np.hypot(own, np.abs(bsdf) * np.linalg.norm(shared_rel, axis=1))
    wi = np.tile([0.0, 0.0, 1.0], (n, 1))
    data = ReducedData(wi, wi, bsdf, sigma, np.ones(n, bool), np.zeros(n, bool), {},
                       shared_rel)
    return data, own


@pytest.mark.parametrize("k", [1, 3, 9])
def test_whitened_residuals_give_the_generalised_chi_square(k):
    rng = np.random.default_rng(k)
    data, own = shared_data(rng, 40, k)
    model = rng.uniform(0.5, 2.0, 40)
    assert np.allclose(data.sigma_own, own, rtol=1e-10)
    u = model[:, None] * data.shared_rel
    cov = np.diag(own**2) + u @ u.T
    r = model - data.bsdf
    assert np.sum(data.whitened(model) ** 2) == pytest.approx(r @ np.linalg.solve(cov, r),
                                                              rel=1e-10)


def test_no_shared_errors_is_the_plain_chi_square():
    rng = np.random.default_rng(1)
    data, own = shared_data(rng, 30, 0)
    model = rng.uniform(0.5, 2.0, 30)
    assert np.array_equal(data.whitened(model), (model - data.bsdf) / data.sigma)
    assert data.subset(np.arange(30) < 10).shared_rel.shape == (10, 0)


def with_common_scale(seed: int, sigma_scale: float) -> ReducedData:
    """Synthetic ground glass at 2e-4 relative noise, every value times one common factor
    1 + e, e ~ N(0, sigma_scale), declared as a shared error (a beam normalisation)."""
    data = synthesize("ggx", 0.394, incidences_deg=(0.0, 30.0), relative_noise=2e-4,
                      dynamic_range=1e7, seed=seed, n_uniform=24, n_peak=12)
    e = sigma_scale * np.random.default_rng(1000 + seed).standard_normal()
    bsdf = data.bsdf * (1.0 + e)
    shared_rel = np.full((len(bsdf), 1), sigma_scale)
    sigma = np.hypot(data.sigma, np.abs(bsdf) * sigma_scale)
    return ReducedData(data.wi, data.wo, bsdf, sigma, data.valid, data.transmission, data.meta,
                       shared_rel)


def test_fit_with_a_common_scale_error_has_a_chi_square_distributed_score():
    """A common 5e-4 scale on 2e-4 point noise: taken as independent per-point noise, chi2/dof
    is 0.14 + 0.86 z^2 for one draw z of the scale (spread 0.48 fitted, 0.42 held out over these
    seeds); as a covariance it is chi-square distributed (spread 0.15, 0.14) with mean 1, on the
    fitted and on the held-out points, and the pulls of alpha stay near 1."""
    options = FitOptions(distributions=("ggx",))
    pulls, fitted, held = [], [], []
    for seed in range(16):
        result = fit(with_common_scale(seed, 5e-4), options)
        value, sigma = result.param("alpha")
        pulls.append((value - 0.394) / sigma)
        fitted.append(result.chi2_dof_fit)
        held.append(result.chi2_dof_heldout)
    assert 0.5 < math.sqrt(np.mean(np.square(pulls))) < 1.5, pulls
    assert 0.8 < np.mean(fitted) < 1.2 and 0.8 < np.mean(held) < 1.2
    assert np.std(fitted) < 0.28 and np.std(held) < 0.28


def test_reduction_shot_noise_matches_the_emulated_meter():
    """Independent route: the scatter of many emulated readings of a bright signal on the
    1e-8 W range against the dark scatter plus emulator_shot_noise_w / averaging times the
    signal."""
    table = {"dark_current_a": 5e-11, "read_noise_fraction": 1e-4}
    meter = PhotodiodeModel(table, seed=4)
    dark = np.array([meter.measure(0.0, 1e-8, 4).reading_w for _ in range(4000)])
    bright = np.array([meter.measure(8e-9, 1e-8, 4).reading_w for _ in range(4000)])
    predicted = dark.var() + emulator_shot_noise_w(table, 632.8) / 4 * 8e-9
    assert bright.var() == pytest.approx(predicted, rel=0.1)
    assert bright.var() > 4.0 * dark.var()  # shot noise dominates: the dark scatter alone fails
