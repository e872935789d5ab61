"""The compiled kernels agree with the numpy reference path (numba is an optional extra)."""

import numpy as np
import pytest

from sim.bsdf import RoughConductor, RoughDielectric
from sim.bsdf.kernels import AVAILABLE

pytestmark = pytest.mark.skipif(not AVAILABLE, reason="numba (gonio[fast]) is not installed")


def _pairs(n=50_000, seed=0):
    rng = np.random.default_rng(seed)
    wi, wo = rng.normal(size=(2, n, 3))
    # extreme rows: grazing, 1e-9 from grazing, normal, unnormalised by 1e-12
    wi[:4] = [[1, 0, 0], [1, 0, 1e-9], [0, 0, 1], [0, 0.6 * (1 + 1e-12), -0.8]]
    wo[:4] = [[0, 0, -1], [-1, 0, 1e-9], [0, 0, 1], [0.3, 0.0, 0.954]]
    return wi / np.linalg.norm(wi, axis=1, keepdims=True), wo / np.linalg.norm(wo, axis=1,
                                                                               keepdims=True)


def _agree(fast, ref):
    """Identical zero pattern; relative differences at rounding level. A 1-ulp difference in a
    direction is amplified by the problem's own conditioning: by X in Beckmann's exp(-X) tails
    (X up to ~700 before underflow) and near grazing facet incidence, hence the max bound."""
    assert np.array_equal(fast > 0, ref > 0)
    rel = np.abs(fast - ref) / np.where(ref > 0, ref, 1.0)
    assert np.quantile(rel, 0.99) < 1e-13
    assert rel.max() < 1e-10
    return rel.max()


@pytest.mark.parametrize("kw", [
    dict(distribution="ggx", alpha=0.3, eta=1.51),
    dict(distribution="ggx", alpha=(0.05, 0.9), eta=1 / 1.33, masking="correlated"),
    dict(distribution="beckmann", alpha=0.4, eta=1.51, sampling="walter"),
    dict(distribution="beckmann", alpha=(1e-3, 2.0), eta=4.0, masking="correlated"),
    dict(distribution="ggx", alpha=0.2, eta=1 + 1e-12, lobes=("transmission",)),
    dict(distribution="beckmann", alpha=0.2, eta=1.51, lobes=("reflection",)),
], ids=str)
def test_dielectric_kernel_matches_numpy(kw):
    wi, wo = _pairs()
    fast, ref = RoughDielectric(**kw), RoughDielectric(backend="numpy", **kw)
    assert fast.backend == "numba"
    _agree(fast.eval(wi, wo), ref.eval(wi, wo))
    _agree(fast.pdf(wi, wo), ref.pdf(wi, wo))


@pytest.mark.parametrize("eta", [None, 0.2 + 3.1j, 1.5 + 0j])
@pytest.mark.parametrize("dist", ["ggx", "beckmann"])
def test_conductor_kernel_matches_numpy(eta, dist):
    wi, wo = _pairs(seed=1)
    fast = RoughConductor(dist, (0.2, 0.4), eta, masking="correlated")
    ref = RoughConductor(dist, (0.2, 0.4), eta, masking="correlated", backend="numpy")
    _agree(fast.eval(wi, wo), ref.eval(wi, wo))
    _agree(fast.pdf(wi, wo), ref.pdf(wi, wo))


def test_phong_falls_back_to_numpy():
    assert RoughDielectric("phong", 0.3).backend == "numpy"
    with pytest.raises(ValueError, match="backend='numba'"):
        RoughDielectric("phong", 0.3, backend="numba")


@pytest.mark.parametrize("kw", [
    dict(), dict(sampling="walter", masking="correlated"),
    dict(alpha=(0.1, 0.5), lobes=("transmission",)), dict(eta=1 / 1.3, lobes=("reflection",)),
    dict(eta=1.0), dict(distribution="beckmann", sampling="walter"),
    dict(distribution="beckmann", alpha=(0.1, 0.6), sampling="walter", masking="correlated",
         eta=1 / 1.4),
], ids=str)
def test_dielectric_sample_kernel_matches_numpy(kw):
    """Same valid samples, directions to 1e-12; weights and pdfs at rounding level except near
    the critical angle, where 1 - F ~ sqrt(e^2 - sin^2) amplifies a 1-ulp difference in m."""
    _sample_agree(RoughDielectric, kw)


@pytest.mark.parametrize("kw", [
    dict(), dict(distribution="ggx", alpha=(0.1, 0.5), eta_complex=0.2 + 3.1j),
    dict(sampling="walter", masking="correlated", eta_complex=1.5 + 0j),
    dict(distribution="beckmann", alpha=0.4, sampling="walter"),
    dict(distribution="beckmann", alpha=(0.2, 0.7), sampling="walter", eta_complex=0.2 + 3.1j,
         masking="correlated"),
], ids=str)
def test_conductor_sample_kernel_matches_numpy(kw):
    _sample_agree(RoughConductor, kw)


def test_beckmann_visible_sampling_stays_numpy():
    """Beckmann's visible-normal sampler needs erfinv (not in numba): numpy path, same model."""
    model = RoughDielectric("beckmann", 0.3, 1.51)
    assert model.backend == "numba" and not model._compiled_sampling()


def _sample_agree(cls, kw):
    rng = np.random.default_rng(3)
    wi, u = rng.normal(size=(50_000, 3)), rng.random((50_000, 3))
    fast, ref = cls(**kw), cls(backend="numpy", **kw)
    assert fast._compiled_sampling()
    (wo_f, w_f, p_f), (wo_r, w_r, p_r) = fast.sample(wi, u), ref.sample(wi, u)
    assert np.array_equal(p_f > 0, p_r > 0) and np.array_equal(np.isinf(p_f), np.isinf(p_r))
    assert np.abs(wo_f - wo_r).max() < 1e-12
    for a, b in ((w_f, w_r), (p_f, p_r)):
        finite = np.isfinite(b)  # eta = 1: every pdf is the Dirac inf, compared above
        a, b = np.append(a[finite], 0.0), np.append(b[finite], 0.0)
        rel = np.abs(a - b) / np.where(b > 0, b, 1.0)
        assert np.quantile(rel, 0.99) < 1e-13 and rel.max() < 1e-9
