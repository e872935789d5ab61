"""The reverse shared-path walk (keyed_kernel.walk_from_starts, keyed.keyed_walk_from_starts)
and lobe.walk_both_ways: each start's estimate against walks from that start alone, and the
transmitted orders >= 3 by reciprocity against the forward walk."""

import numpy as np
import pytest

from model.bsdf import RoughDielectric
from model.bsdf.distributions import make_distribution
from model.bsdf.multiple_scattering import keyed, nee_kernel
from model.bsdf.multiple_scattering.keyed import keyed_walk_from_starts, keyed_walk_to_targets
from model.bsdf.multiple_scattering.lobe import walk_both_ways
from model.bsdf.multiple_scattering.micro import MicroDielectric
from model.bsdf.multiple_scattering.model import RandomWalkBSDF
from model.bsdf.multiple_scattering.walk import Walker

pytestmark = pytest.mark.skipif(not nee_kernel.AVAILABLE, reason="numba is not installed")
Z_MAX = 4.5  # |z-score| allowed for a Monte Carlo comparison (deterministic seeds)


def directions(theta_deg, phi_deg=0.0):
    t, p = np.radians(np.asarray(theta_deg, float)), np.radians(phi_deg)
    return np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1)


@pytest.mark.parametrize("name,starts,target", [
    ("ggx", directions([100.0, 120.0, 140.0, 160.0, 178.0]), directions(0.0)),  # from inside
    ("beckmann", directions([5.0, 40.0, 70.0, 88.0], 60.0), directions(150.0, 10.0)),
    ("ggx", directions([20.0, 50.0, 80.0], 200.0), directions(30.0)),  # reflected, from above
])
def test_every_start_matches_walks_from_it_alone(name, starts, target):
    """Cost ~2 s: 2^16 shared walks against 2^15 from each start alone (orders >= 3)."""
    walker = Walker(make_distribution(name, 0.5), MicroDielectric(1.51), guided=False)
    mean, err, cov = keyed_walk_from_starts(walker, starts, target, 1 << 16,
                                            np.random.default_rng(1), min_order=3)
    for b, start in enumerate(starts):
        ref, ref_err, _ = keyed_walk_to_targets(walker, start, target[None, :], 1 << 15,
                                                np.random.default_rng(10 + b), 3, False)
        assert ref[0] > 0.0 and 0.0 < err[b] < 0.25 * mean[b]  # a usable estimate
        assert abs(mean[b] - ref[0]) < Z_MAX * np.hypot(err[b], ref_err[0]), (b, mean, ref)
    np.testing.assert_allclose(np.diag(cov), err ** 2, rtol=1e-12)


def test_transmitted_targets_by_reciprocity_match_the_forward_walk():
    """Cost ~3 s: glass lit from above and from inside, transmitted and reflected targets."""
    walk = RandomWalkBSDF(RoughDielectric(distribution="ggx", alpha=0.4, eta=1.51,
                                          masking="correlated"), walks=1, guided=False)
    for wi, targets in ((directions(0.0), directions([30.0, 110.0, 130.0, 160.0])),
                        (directions(150.0, 180.0), directions([20.0, 60.0, 100.0, 170.0]))):
        both, both_err, cov = walk_both_ways(walk, wi, targets, 1 << 17,
                                             np.random.default_rng(2), min_order=3)
        fwd, fwd_err, _ = keyed_walk_to_targets(walk.walker, wi, targets, 1 << 19,
                                                np.random.default_rng(3), 3, False)
        z = (both - fwd) / np.hypot(both_err, fwd_err)
        assert np.all(both > 0.0) and np.all(np.abs(z) < Z_MAX), z
        np.testing.assert_allclose(np.diag(cov), both_err ** 2, rtol=1e-12)
        np.testing.assert_array_equal(cov, cov.T)
        if wi[2] == 1.0:  # the normal-incidence wings go backwards: not the reflected's walks
            assert np.all(cov[0, 1:3] == 0.0) and cov[1, 2] > 0.0


def test_starts_on_both_sides_and_order_1_are_refused():
    walker = Walker(make_distribution("ggx", 0.5), MicroDielectric(1.51), guided=False)
    with pytest.raises(ValueError, match="one side"):
        keyed_walk_from_starts(walker, directions([30.0, 120.0]), directions(0.0), 64,
                               np.random.default_rng(0))
    with pytest.raises(ValueError, match="min_order must be >= 2"):
        keyed_walk_from_starts(walker, directions([120.0]), directions(0.0), 64,
                               np.random.default_rng(0), min_order=1)


@pytest.mark.parametrize("theta_i,targets,most", [
    (0.0, directions([110.0, 120.0, 130.0]), 0.5),  # normal incidence, transmitted wing
    (60.0, directions([130.0, 160.0, 180.0], 180.0), 1.15),  # oblique: the forward walk wins
])
def test_the_pilot_keeps_the_better_direction(theta_i, targets, most):
    """Cost ~2 s: walk_both_ways' error against the forward walk's alone at the same walks:
    far below it where the reverse walk wins, not above it (beyond the pilot's own cost in
    noise) where it loses."""
    walk = RandomWalkBSDF(RoughDielectric(distribution="ggx", alpha=0.4, eta=1.51,
                                          masking="correlated"), walks=1, guided=False)
    wi = directions(theta_i)
    _, both_err, _ = walk_both_ways(walk, wi, targets, 1 << 17, np.random.default_rng(4), 3)
    _, fwd_err, _ = keyed_walk_to_targets(walk.walker, wi, targets, 1 << 17,
                                          np.random.default_rng(5), 3, False)
    assert np.all(both_err < most * fwd_err), (both_err, fwd_err)


@pytest.mark.parametrize("targets", [
    directions([10.0, 140.0, 170.0]),
    directions(np.linspace(95.0, 179.0, 600)),  # batches of MIN_BATCH_WALKS walks
])
def test_the_result_does_not_depend_on_the_threads(monkeypatch, targets):
    """Keyed walks draw from their own index and the batches do not depend on the threads:
    one thread or several give the same numbers, bit for bit."""
    walk = RandomWalkBSDF(RoughDielectric(distribution="beckmann", alpha=0.3, eta=1.51,
                                          masking="correlated"), walks=1, guided=False)
    runs = []
    for threads in (1, 2):
        monkeypatch.setattr(keyed, "THREADS", threads)
        runs.append(walk_both_ways(walk, directions(20.0), targets, 1 << 12,
                                   np.random.default_rng(6), 2))
    for one, many in zip(*runs, strict=True):
        np.testing.assert_array_equal(one, many)
    assert np.all(np.isfinite(runs[0][2]))  # nearly dark targets (sd ~1e-160) included


def test_one_kernel_thread_where_numba_has_one(monkeypatch):
    """model.cluster's policy (numba's thread count 1 in a Dask task) holds for the walks."""
    numba = pytest.importorskip("numba")
    monkeypatch.setattr(keyed, "THREADS", 2)
    previous = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        assert keyed._threads() == 1
    finally:
        numba.set_num_threads(previous)
    assert keyed._threads() == min(2, previous)
