"""Energy of the microsurface: what single scattering misses, and directional albedo by Monte Carlo.

energy_loss is deterministic (Gauss-Legendre quadrature over visible normals of the exact
order-1 energy with height-correlated masking), cheap enough for the bench to decide whether
multiple scattering is worth computing. albedo_estimate integrates any model's f |cos o| over
the sphere by importance sampling, the white-furnace check of the random walk.
"""

from __future__ import annotations

import numpy as np

from sim.bsdf.distributions import make_distribution
from sim.bsdf.fresnel import dielectric_reflectance_transmittance
from sim.bsdf.masking import check_masking, log_beta
from sim.bsdf.multiple_scattering.walk import flip, walkable


def _gauss_legendre_unit(n: int) -> tuple[np.ndarray, np.ndarray]:
    x, w = np.polynomial.legendre.leggauss(n)
    return 0.5 * (x + 1.0), 0.5 * w


def single_scattering_energy(
    distribution: str, alpha, eta: float | None, theta: float, masking: str = "correlated",
    nodes: int = 48,
) -> float:
    """Energy (R + T) that single scattering returns at incidence theta (radians), lossless facets.

    eta None (or complex) means a mirror conductor (F = 1): the upper bound of what a conductor
    loses. Energy per visible normal m, with Lo the Lambda of the reflected / refracted w_o:
    "correlated" (height-correlated Smith, = order 1 of the walk): reflection
    (1 + Li)/(1 + Li + Lo), transmission (1 + Li) B(1 + Li, 1 + Lo); "separable": 1/(1 + Lo).
    """
    check_masking(masking)
    if not 0.0 <= theta < 0.5 * np.pi:
        raise ValueError(f"theta must lie in [0, pi/2) radians, got {theta!r}")
    slopes = walkable(make_distribution(distribution, alpha))
    x, w = _gauss_legendre_unit(nodes)
    u1, u2 = (a.ravel() for a in np.meshgrid(x, x, indexing="ij"))
    weights = np.outer(w, w).ravel()
    wi = np.broadcast_to([np.sin(theta), 0.0, np.cos(theta)], u1.shape + (3,))
    m = slopes.sample_visible_sphere(wi, u1, u2)
    c = np.clip(np.sum(wi * m, axis=-1), 0.0, 1.0)
    li = slopes.signed_lambda(wi[:1])[0]
    wr = 2.0 * c[:, None] * m - wi
    lr = slopes.signed_lambda(wr)
    correlated = masking == "correlated"
    refl = np.where(wr[:, 2] > 0.0, (1.0 + li) / (1.0 + li + lr) if correlated else
                    1.0 / (1.0 + lr), 0.0)
    if eta is None or np.iscomplexobj(eta):
        return float(np.sum(weights * refl))
    fr, _ = dielectric_reflectance_transmittance(c, float(eta))
    sin2 = (1.0 - c * c) / eta**2
    cos_t = np.sqrt(np.maximum(0.0, 1.0 - sin2))
    wt = -wi / eta + (c / eta - cos_t)[:, None] * m
    wt_up = flip(wt / np.linalg.norm(wt, axis=-1, keepdims=True))
    lt = slopes.signed_lambda(wt_up)
    seen = (wt_up[:, 2] > 0.0) & np.isfinite(lt)  # Lambda = inf (grazing): masked, G = 0
    lt = np.where(seen, lt, 0.0)
    g = (1.0 + li) * np.exp(log_beta(1.0 + li, 1.0 + lt)) if correlated else 1.0 / (1.0 + lt)
    trans = np.where(seen, g, 0.0)
    return float(np.sum(weights * (fr * refl + (1.0 - fr) * np.nan_to_num(trans))))


def energy_loss(distribution: str, alpha, eta: float | complex | None, theta: float,
                masking: str = "correlated") -> float:
    """Fraction of the incident energy a single-scattering model loses at incidence theta.

    For a dielectric it is exactly what the random walk adds back (R + T = 1); for a conductor
    it is the F = 1 value, an upper bound of the multiply scattered energy. masking names the
    single-scattering model in use ("correlated" or "separable", as in sim.bsdf).
    """
    return 1.0 - single_scattering_energy(distribution, alpha, eta, theta, masking)


def albedo_estimate(model, wi: np.ndarray, rng: np.random.Generator, samples: int,
                    **eval_options) -> tuple[float, float]:
    """Integral of f(wi, wo) |cos o| over all wo, and its standard error, by importance sampling.

    Proposal: the mixture of a cosine-weighted lobe about +z and one about -z (pdf |cos o| /
    (2 pi)), so both reflection and transmission are covered; model.eval(wi, wo, rng) is
    called once for all the samples.
    """
    wi = np.asarray(wi, dtype=np.float64)
    u = rng.random((samples, 3))
    r = np.sqrt(u[:, 0])
    phi = 2.0 * np.pi * u[:, 1]
    z = np.sqrt(np.maximum(0.0, 1.0 - u[:, 0])) * np.where(u[:, 2] < 0.5, 1.0, -1.0)
    wo = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=-1)
    pdf = 0.5 * np.abs(z) / np.pi
    f = model.eval(np.broadcast_to(wi, wo.shape), wo, rng, **eval_options)
    terms = np.where(pdf > 0.0, f * np.abs(z) / np.where(pdf > 0.0, pdf, 1.0), 0.0)
    return float(terms.mean()), float(terms.std(ddof=1) / np.sqrt(samples))
