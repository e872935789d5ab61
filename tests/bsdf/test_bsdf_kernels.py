"""The compiled kernels agree with the numpy reference path (numba is an optional extra)."""

import bsdf_reference as ref
import numpy as np
import pytest

from model.bsdf import RoughConductor, RoughDielectric
from model.bsdf.distributions import WITH_KERNELS
from model.bsdf.kernels import AVAILABLE

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
    dict(distribution="ggx", alpha=(0.2, 0.6), eta=1 / 1.51, lobes=("reflection",)),
    dict(distribution="ggx", alpha=1e-4, eta=4.0, sampling="walter"),
    dict(distribution="ggx", alpha=4.0, eta=0.25, masking="correlated"),
], ids=str)
def test_dielectric_kernel_matches_numpy(kw):
    wi, wo = _pairs()
    fast, ref = RoughDielectric(**kw), RoughDielectric(backend="numpy", **kw)
    assert fast.backend == "numba"
    _agree(fast.eval(wi, wo), ref.eval(wi, wo))
    _agree(fast.pdf(wi, wo), ref.pdf(wi, wo))


@pytest.mark.parametrize("eta", [None, 0.2 + 3.1j, 1.5 + 0j])
@pytest.mark.parametrize("dist", WITH_KERNELS)
def test_conductor_kernel_matches_numpy(eta, dist):
    wi, wo = _pairs(seed=1)
    fast = RoughConductor(dist, (0.2, 0.4), eta, masking="correlated")
    ref = RoughConductor(dist, (0.2, 0.4), eta, masking="correlated", backend="numpy")
    _agree(fast.eval(wi, wo), ref.eval(wi, wo))
    _agree(fast.pdf(wi, wo), ref.pdf(wi, wo))


@pytest.mark.parametrize("kw", [
    dict(alpha=0.3, eta=1.51), dict(alpha=(0.05, 0.9), eta=1 / 1.33, masking="correlated"),
    dict(alpha=1e-3, eta=4.0), dict(alpha=3.0, eta=0.25),
], ids=str)
def test_ggx_simd_eval_matches_mpmath(kw):
    """The GGX SIMD block (rearranged formulas: 3 sqrt, 1 division) against Walter's formulas
    at 50 digits on random pairs of both sides, TIR included: as accurate as the numpy path
    (worst 3e-14 over these pairs, the numpy path's worst the same)."""
    rng = np.random.default_rng(5)
    wi, wo = rng.normal(size=(2, 120, 3))
    ours = RoughDielectric("ggx", **kw).eval(wi, wo)
    alpha = kw["alpha"] if isinstance(kw["alpha"], tuple) else (kw["alpha"],) * 2
    exact = np.array([float(ref.eval_dielectric("ggx", alpha, kw["eta"],
                                                kw.get("masking", "separable"), a, b))
                      for a, b in zip(wi, wo, strict=True)])
    assert np.array_equal(ours > 0, exact > 0) and (exact > 0).sum() > 60
    assert (np.abs(ours - exact) / np.where(exact > 0, exact, 1.0)).max() < 1e-13


@pytest.mark.parametrize("kw", [dict(), dict(masking="correlated", lobes=("transmission",))],
                         ids=str)
def test_ggx_simd_input_layouts(kw):
    """Broadcast and strided inputs give the contiguous result bit for bit; directions off unit
    length (normalised by a series within 1e-6, beyond it the block is normalised and run
    again) agree with the unit ones and with the numpy path as the kernels agree with numpy."""
    wi, wo = _pairs(20_000, seed=4)
    model = RoughDielectric("ggx", 0.3, 1.51, **kw)
    for want_pdf in (False, True):
        f = model.pdf if want_pdf else model.eval
        unit = f(wi, wo)
        one = np.broadcast_to(wi[7], wo.shape)
        assert np.array_equal(f(one, wo), f(np.ascontiguousarray(one), wo))
        assert np.array_equal(f(wi[::2], wo[::2]), unit[::2])
        assert np.array_equal(f(wi[:1], wo[:1]), unit[:1])
        # scaled values round differently: _agree, without the 1e-9-from-grazing rows, where
        # wi + wo cancels to 1e-9 and a 1-ulp change of a direction moves f by 1e-7
        for scale in (1 + 3e-7, 3.7, 1e-30):
            _agree(f(wi[4:] * scale, wo[4:] / scale), unit[4:])
        ref_path = RoughDielectric("ggx", 0.3, 1.51, backend="numpy", **kw)
        _agree(f(wi[4:] * 3.7, wo[4:]),
               (ref_path.pdf if want_pdf else ref_path.eval)(wi[4:], wo[4:]))


def test_phong_falls_back_to_numpy():
    assert RoughDielectric("phong", 0.3).backend == "numpy"
    with pytest.raises(ValueError, match="backend='numba'"):
        RoughDielectric("phong", 0.3, backend="numba")


@pytest.mark.parametrize("kw", [
    dict(), dict(sampling="walter", masking="correlated"),
    dict(alpha=(0.1, 0.5), lobes=("transmission",)), dict(eta=1 / 1.3, lobes=("reflection",)),
    dict(eta=1.0), dict(distribution="beckmann", sampling="walter"),
    dict(masking="correlated"), dict(alpha=(0.05, 0.9), eta=1 / 1.4, masking="correlated"),
    dict(alpha=1e-4, eta=4.0, lobes=("transmission",)), dict(alpha=4.0, eta=0.25),
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


def test_ggx_simd_sample_input_layouts():
    """One wi broadcast against many u and strided inputs give the contiguous result bit for
    bit; wi off unit length and u at the ends of [0, 1] agree with the numpy path."""
    rng = np.random.default_rng(6)
    wi, u = rng.normal(size=(20_000, 3)), rng.random((20_000, 3))
    u[:6] = [[0, 0, 0], [1, 1, 1], [0, 0.25, 0.5], [1, 0.75, 0], [0.5, 1 - 1e-16, 1], [0, 1, 0]]
    model = RoughDielectric("ggx", 0.3, 1.51)
    one = np.broadcast_to(wi[3], wi.shape)
    for a, b in ((model.sample(one, u), model.sample(np.ascontiguousarray(one), u)),
                 (model.sample(wi[::2], u[::2]), tuple(x[::2] for x in model.sample(wi, u)))):
        assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
    _sample_agree(RoughDielectric, dict(alpha=0.3, eta=1.51), wi * 3.7, u)


def _sample_agree(cls, kw, wi=None, u=None):
    if wi is None:
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


@pytest.mark.parametrize("model", [
    RoughDielectric(distribution="ggx", alpha=0.3, eta=1.51),
    RoughDielectric(distribution="ggx", alpha=(0.05, 0.9), eta=1 / 1.33, masking="correlated"),
    RoughDielectric(distribution="beckmann", alpha=0.4, eta=1.51, sampling="walter"),
    RoughConductor(distribution="ggx", alpha=0.25, eta_complex=0.2 + 3.4j),
], ids=["ggx", "ggx-correlated", "beckmann", "conductor"])
def test_serial_and_parallel_kernels_agree_bit_for_bit(model, monkeypatch):
    """Small batches run on the calling thread (kernels.SERIAL_BELOW): the same pairs give the
    same bits either way, eval and pdf."""
    import model.bsdf.kernels as kernels

    wi, wo = _pairs(5000, seed=3)
    runs = []
    for serial_below in (0, len(wi) + 1):
        monkeypatch.setattr(kernels, "SERIAL_BELOW", serial_below)
        runs.append((model.eval(wi, wo), model.pdf(wi, wo)))
    (eval_par, pdf_par), (eval_ser, pdf_ser) = runs
    assert np.array_equal(eval_par, eval_ser) and np.array_equal(pdf_par, pdf_ser)
    assert np.count_nonzero(eval_par) > 1000
