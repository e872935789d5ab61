"""alpha given as an array (one roughness per direction pair, as the LUT baker uses it) matches
the scalar models. Per-pair alpha is supported where every pair falls in the same lobe
(one-lobe models, or sample()); mixed-lobe eval needs one alpha (docs/bsdf.md)."""

import numpy as np

from model.bsdf import RoughDielectric


def test_per_pair_alpha_matches_scalar_models_for_eval_and_sample():
    rng = np.random.default_rng(7)
    alphas = np.array([0.05, 0.3, 0.8])
    wi = np.array([[0.3, 0.1, 0.9], [-0.5, 0.2, 0.6], [0.0, 0.7, 0.2]])
    wi /= np.linalg.norm(wi, axis=-1, keepdims=True)
    wo = np.array([[-0.2, 0.0, -0.95], [0.4, -0.1, -0.8], [0.1, -0.6, -0.3]])
    wo /= np.linalg.norm(wo, axis=-1, keepdims=True)
    u = rng.random((3, 3))
    batch = RoughDielectric("ggx", alpha=alphas, eta=1.51)
    f = batch.eval(wi, wo)
    wo_s, weight, pdf = batch.sample(wi, u)
    for k, a in enumerate(alphas):
        single = RoughDielectric("ggx", alpha=a, eta=1.51)
        assert np.isclose(f[k], single.eval(wi[k], wo[k]), rtol=1e-10, atol=0)
        wo_k, weight_k, pdf_k = single.sample(wi[k:k + 1], u[k:k + 1])
        assert np.allclose(wo_s[k], wo_k[0], rtol=1e-9, atol=1e-12)
        assert np.isclose(weight[k], weight_k[0], rtol=1e-9)
        assert np.isclose(pdf[k], pdf_k[0], rtol=1e-9)
