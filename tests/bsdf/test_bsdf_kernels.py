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
