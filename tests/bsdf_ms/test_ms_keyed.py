"""The keyed, branch-split shared-path walk (keyed.py, keyed_kernel.py) behind walk_to_targets:
its orders >= 3 against the walk's own (Walker.run(min_order=3), sequential, F-chosen
branches), walks that do not depend on the batch, and the covariance it states."""

import numpy as np
import pytest

from model.bsdf.distributions import make_distribution
from model.bsdf.multiple_scattering import keyed, nee_kernel
from model.bsdf.multiple_scattering.keyed import keyed_walk_to_targets
from model.bsdf.multiple_scattering.micro import MicroConductor, MicroDielectric
from model.bsdf.multiple_scattering.walk import Walker

pytestmark = pytest.mark.skipif(not nee_kernel.AVAILABLE, reason="numba is not installed")
Z_MAX = 4.5  # |z-score| allowed for a Monte Carlo comparison (deterministic seeds)


def directions(theta_deg, phi_deg=0.0):
    t, p = np.radians(np.asarray(theta_deg, float)), np.radians(phi_deg)
    return np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1)


TARGETS = directions([10.0, 45.0, 80.0, 100.0, 135.0, 175.0], 30.0)


@pytest.mark.parametrize("name,micro,wi", [
    ("ggx", MicroDielectric(1.51), directions(0.0)),  # glass from above
    ("beckmann", MicroDielectric(1.51), -directions(35.0, 180.0)),  # from inside (TIR)
    ("ggx", MicroConductor(0.2 + 3.4j), directions(50.0)),  # gold-like
])
def test_orders_three_and_up_match_the_walk(name, micro, wi):
    """Cost ~1 s: 2^16 walks of each estimator towards 6 targets."""
    walker = Walker(make_distribution(name, 0.6), micro, guided=False)
    n = 1 << 16
    mean, err, cov = keyed_walk_to_targets(walker, wi, TARGETS, n, np.random.default_rng(3),
                                           min_order=3)
    plain = walker.run(np.repeat(wi[None, :], n, axis=0), np.random.default_rng(4),
                       targets=TARGETS, min_order=3).value
    ref, ref_err = plain.mean(axis=0), plain.std(axis=0) / np.sqrt(n)
    live = ref > 0.0
    assert live.sum() >= 3 and np.all(mean[~live] == 0.0)
    z = (mean - ref)[live] / np.hypot(err, ref_err)[live]
    assert np.all(np.abs(z) < Z_MAX), z
    np.testing.assert_allclose(np.diag(cov), err ** 2, rtol=1e-12)


def test_walks_do_not_depend_on_the_batch(monkeypatch):
    """Walk j is the same path in any batch: the estimate is the same in batches of 256."""
    walker = Walker(make_distribution("ggx", 0.4), MicroDielectric(1.51), guided=False)
    wi = directions(20.0)
    one = keyed_walk_to_targets(walker, wi, TARGETS, 3000, np.random.default_rng(5))
    monkeypatch.setattr(keyed, "BATCH_SCORES", 256 * len(TARGETS))
    monkeypatch.setattr(keyed, "MIN_BATCH_WALKS", 256)
    split = keyed_walk_to_targets(walker, wi, TARGETS, 3000, np.random.default_rng(5))
    for a, b in zip(one, split, strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=0.0)
    other = keyed_walk_to_targets(walker, wi, TARGETS, 3000, np.random.default_rng(6))
    assert not np.allclose(one[0], other[0])


def test_covariance_is_the_first_walks_correlation_scaled():
    """The stated covariance: diagonal the squared errors, a correlation matrix inside, and the
    correlation of neighbouring targets (shared walks) positive. Cost ~0.1 s."""
    walker = Walker(make_distribution("ggx", 0.5), MicroDielectric(1.51), guided=False)
    near = directions(np.arange(20.0, 40.0, 2.0))
    _, err, cov = keyed_walk_to_targets(walker, directions(0.0), near, 1 << 15,
                                        np.random.default_rng(7), min_order=2)
    corr = cov / np.outer(err, err)
    np.testing.assert_allclose(np.diag(corr), 1.0, rtol=1e-12)
    assert np.all(np.abs(corr) <= 1.0 + 1e-12) and np.all(corr[0, 1:3] > 0.5)
    assert np.min(np.linalg.eigvalsh(corr)) > -1e-8
