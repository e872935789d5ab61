"""Height-correlated transmission in the GGX SIMD blocks: the Beta-function G2, multiplied in
after the block, agrees with the per-pair scalar kernels, the numpy path and mpmath at 50
digits out to extreme Lambda (grazing directions, Lambda up to ~1e20)."""

import bsdf_reference as ref
import mpmath as mp
import numpy as np
import pytest

from model.bsdf import RoughDielectric, kernels
from model.bsdf.constants import Masking, Ndf, Sampling

pytestmark = pytest.mark.skipif(not kernels.AVAILABLE,
                                reason="numba (gonio[fast]) is not installed")

ALPHA, ETA = (0.3, 1.3), 1.51
#: The per-pair kernels' int arguments (kernels.dielectric converts the enums the same way).
GGX, CORRELATED, VISIBLE = int(Ndf.GGX), int(Masking.CORRELATED), int(Sampling.VISIBLE)


def _directions(rng, n, lowest):
    """n unit directions, random azimuth and side, |cos| log-uniform from lowest to 1."""
    cos = 10.0 ** rng.uniform(np.log10(lowest), 0.0, n)
    phi = rng.uniform(0.0, 2.0 * np.pi, n)
    sin = np.sqrt((1.0 - cos) * (1.0 + cos))
    side = np.where(rng.random(n) < 0.5, -1.0, 1.0)
    return np.stack([sin * np.cos(phi), sin * np.sin(phi), side * cos], axis=1)


def _transmitted_pairs(n, seed, lowest=1e-20):
    rng = np.random.default_rng(seed)
    wi, wo = _directions(rng, n, lowest), _directions(rng, n, lowest)
    wo[:, 2] = -np.sign(wi[:, 2]) * np.abs(wo[:, 2])
    return wi, wo


def _log_scaled_error(fast, slow):
    """|fast - slow| / slow / max(1, |log slow|) (0 where slow is 0): exp of a log-form Beta
    is only good to |log B| eps, and log B reaches -700 at grazing directions."""
    live = np.where(slow > 0, slow, 1.0)
    return np.abs(fast - slow) / live / np.maximum(1.0, np.abs(np.log(live)))


def _close(fast, slow, least=300):
    """Same zero pattern; differences at rounding level relative to |log f| (99 %), bounded
    (all). (Two independent grazing directions rarely make a transmitted pair: few are live.)"""
    assert np.array_equal(fast > 0, slow > 0) and (slow > 0).sum() > least
    rel = _log_scaled_error(fast, slow)
    assert np.quantile(rel, 0.99) < 1e-14 and rel.max() < 1e-11


@pytest.mark.parametrize("alpha, eta", [(ALPHA, ETA), ((0.05, 0.9), 1 / 1.33), ((4.0, 4.0), 0.25)])
def test_correlated_eval_block_matches_scalar_kernel_and_numpy(alpha, eta):
    wi, wo = _transmitted_pairs(20_000, 1)
    model = RoughDielectric("ggx", alpha, eta, masking="correlated")
    fast = model.eval(wi, wo)
    scalar = kernels._dielectric(wi, wo, GGX, *alpha, eta, CORRELATED, True, True, VISIBLE,
                                 False)
    _close(fast, scalar)
    ref_path = RoughDielectric("ggx", alpha, eta, masking="correlated", backend="numpy")
    _close(fast, ref_path.eval(wi, wo))


def test_correlated_eval_matches_mpmath_at_extreme_lambda():
    """Lambda up to ~1e20 on either side: the log-form Beta (Stirling regions) keeps the block
    path as accurate as |log f| eps allows, against mpmath's Beta at 50 digits."""
    wi, wo = _transmitted_pairs(4000, 2)
    model = RoughDielectric("ggx", ALPHA, ETA, masking="correlated")
    wi, wo = wi[model.eval(wi, wo) > 0], wo[model.eval(wi, wo) > 0]
    wi, wo = np.concatenate([wi, [[0.6, 0, 1e-20]]]), np.concatenate([wo, [[-0.6, 0, -0.8]]])
    exact_mp = [ref.eval_dielectric("ggx", ALPHA, ETA, "correlated", a, b)
                for a, b in zip(wi, wo, strict=True)]
    exact = np.array([float(x) for x in exact_mp])  # 0 where below the double range
    ours = model.eval(wi, wo)
    assert np.array_equal(ours > 0, exact > 0) and (exact > 0).sum() > 30
    lam = [float(ref.Lambda("ggx", ALPHA, w)) for w in np.concatenate([wi, wo])]
    assert max(lam) > 1e15  # the Stirling regions of log B are reached
    assert _log_scaled_error(ours, exact).max() < 1e-14


def _sample_weight_exact(wi, wo):
    """Weight of a transmitted sample with both lobes: (1 + Lambda_i) B(1 + Lambda_i,
    1 + Lambda_o) (f |cos o| / pdf, Fresnel cancelling the lobe choice), at 50 digits."""
    li, lo = ref.Lambda("ggx", ALPHA, wi), ref.Lambda("ggx", ALPHA, wo)
    return (1 + li) * mp.beta(1 + li, 1 + lo)


def test_correlated_sample_weight_matches_mpmath_at_extreme_lambda():
    rng = np.random.default_rng(3)
    wi, u = _directions(rng, 400, 1e-20), rng.random((400, 3))
    wo, weight, pdf = RoughDielectric("ggx", ALPHA, ETA, masking="correlated").sample(wi, u)
    transmitted = (pdf > 0) & (wo[:, 2] * wi[:, 2] < 0)
    exact = np.array([float(_sample_weight_exact(a, b)) for a, b in
                      zip(wi[transmitted], wo[transmitted], strict=True)])
    assert (exact > 0).sum() > 100 and np.log(exact[exact > 0]).min() < -100
    assert _log_scaled_error(weight[transmitted], exact).max() < 1e-14


@pytest.mark.parametrize("kw", [
    dict(alpha=ALPHA, eta=ETA), dict(alpha=(0.05, 0.9), eta=1 / 1.4),
    dict(alpha=(4.0, 4.0), eta=0.25, lobes=("transmission",)),
    dict(alpha=(1e-3, 1e-3), eta=4.0, lobes=("transmission",)),
], ids=str)
def test_correlated_sample_block_matches_scalar_kernel(kw):
    """The block plus Beta pass against the per-pair scalar sampler on grazing and ordinary
    wi: same valid samples, directions to 1e-12, weights and pdfs at rounding level (relative
    to |log|: the two round log B differently, and exp turns that into |log B| eps)."""
    rng = np.random.default_rng(4)
    wi, u = _directions(rng, 40_000, 1e-20), rng.random((40_000, 3))
    model = RoughDielectric("ggx", masking="correlated", **kw)
    wo_f, w_f, p_f = model.sample(wi, u)
    wo_s, w_s, p_s = kernels._dielectric_sample(wi, u, GGX, *kw["alpha"], kw["eta"], CORRELATED,
                                                model.reflection, model.transmission, VISIBLE)
    assert (wo_f[:, 2] * wi[:, 2] < 0).sum() > 5000
    assert np.abs(wo_f - wo_s).max() < 1e-12
    _close(w_f, w_s)
    _close(p_f, p_s)


def test_correlated_sample_input_layouts():
    """Broadcast and strided inputs give the contiguous result bit for bit."""
    rng = np.random.default_rng(6)
    wi, u = rng.normal(size=(20_000, 3)), rng.random((20_000, 3))
    model = RoughDielectric("ggx", 0.3, 1.51, masking="correlated")
    one = np.broadcast_to(wi[3], wi.shape)
    for a, b in ((model.sample(one, u), model.sample(np.ascontiguousarray(one), u)),
                 (model.sample(wi[::2], u[::2]), tuple(x[::2] for x in model.sample(wi, u)))):
        assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
