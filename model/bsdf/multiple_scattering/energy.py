"""Energy of the microsurface: what single scattering misses, and directional albedo by Monte Carlo.

energy_loss is deterministic (graded Gauss-Legendre quadrature, over the facets' slopes, of
what each facet's single scattering loses: accurate for losses down to 1e-6 and below),
cheap enough for the bench to decide whether multiple scattering is worth computing.
albedo_estimate integrates any model's f |cos o| over the sphere by importance sampling, the
white-furnace check of the random walk.
"""

from __future__ import annotations

import numpy as np

from model.bsdf.distributions import make_distribution
from model.bsdf.fresnel import dielectric_reflectance_transmittance
from model.bsdf.masking import check_masking, log_beta
from model.bsdf.multiple_scattering.walk import flip, walkable

#: Gauss-Legendre nodes per panel, halvings of the panels towards each end of a stretch
#: between breakpoints, and nodes per quarter turn of the slope azimuth.
PANEL_NODES = 5
GRADING = 10
AZIMUTH_NODES = 16


def gauss_legendre_unit(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Nodes and weights of n-point Gauss-Legendre on [0, 1]."""
    x, w = np.polynomial.legendre.leggauss(n)
    return 0.5 * (x + 1.0), 0.5 * w


def _graded_unit_rule() -> tuple[np.ndarray, np.ndarray]:
    """Nodes and weights on [0, 1]: PANEL_NODES-point panels halving towards both ends
    GRADING times, so a stretch resolves what happens within 2^-GRADING of a breakpoint."""
    edges = 0.5 * 0.5 ** np.arange(GRADING + 1)
    edges = np.concatenate([[0.0], edges[::-1], 1.0 - edges[1:], [1.0]])
    x, w = gauss_legendre_unit(PANEL_NODES)
    width = np.diff(edges)
    return (edges[:-1, None] + width[:, None] * x).ravel(), (width[:, None] * w).ravel()


def _slope_normals(slopes, psi: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """Normals of unit-roughness slope tan(psi) at azimuth phi, stretched to the surface."""
    rho = np.tan(psi)
    sx, sy = slopes.alpha_x * rho * np.cos(phi), slopes.alpha_y * rho * np.sin(phi)
    inv = 1.0 / np.sqrt(1.0 + sx * sx + sy * sy)
    return np.stack([-sx * inv, -sy * inv, inv], axis=-1)


def _radial_density(slopes, psi: np.ndarray) -> np.ndarray:
    """P(rho) rho drho/dpsi of the unit-roughness slope rho = tan(psi) (either distribution)."""
    if slopes.name == "ggx":
        return np.sin(psi) * np.cos(psi) / np.pi
    t = np.tan(psi)
    with np.errstate(over="ignore", invalid="ignore"):
        value = np.exp(-t * t) * t / (np.pi * np.cos(psi) ** 2)
    return np.nan_to_num(value)


def _refracted(wi: np.ndarray, m: np.ndarray, c: np.ndarray, eta: float) -> np.ndarray:
    """Direction refracted through m into the medium eta times denser (unit; TIR: zeros)."""
    sin2 = (1.0 - c * c) / eta**2
    cos_t = np.sqrt(np.maximum(0.0, 1.0 - sin2))
    wt = -wi / eta + (c / eta - cos_t)[..., None] * m
    norm = np.linalg.norm(wt, axis=-1, keepdims=True)
    return np.where(sin2[..., None] < 1.0, wt / np.where(norm > 0.0, norm, 1.0), 0.0)


def _loss_per_normal(slopes, wi, m, eta, correlated: bool) -> np.ndarray:
    """Energy the single-scattering model misses from the facets m (...,3): reflection
    Lo/(1+Li+Lo) (correlated) or Lo/(1+Lo), all of it past the horizon; transmission
    1 - (1+Li) B(1+Li, 1+Lt) or Lt/(1+Lt), weighted by Fresnel (F = 1 without eta)."""
    c = np.clip(np.sum(wi * m, axis=-1), 0.0, 1.0)
    li = slopes.signed_lambda(wi)
    wr = 2.0 * c[..., None] * m - wi
    with np.errstate(invalid="ignore", divide="ignore"):
        lr = slopes.signed_lambda(wr)
        lost_r = lr / (1.0 + li + lr) if correlated else lr / (1.0 + lr)
    lost_r = np.where(wr[..., 2] > 0.0, np.where(np.isfinite(lr), lost_r, 1.0), 1.0)
    if eta is None:
        return lost_r
    fr, _ = dielectric_reflectance_transmittance(c, eta)
    wt_up = flip(_refracted(wi, m, c, eta))
    seen = wt_up[..., 2] > 0.0
    with np.errstate(invalid="ignore", divide="ignore"):
        lt = np.where(seen, slopes.signed_lambda(wt_up), 0.0)
        if correlated:
            lost_t = -np.expm1(np.log1p(li) + log_beta(1.0 + li, 1.0 + lt))
        else:
            lost_t = lt / (1.0 + lt)
    lost_t = np.where(seen & np.isfinite(lt), lost_t, 1.0)
    return fr * lost_r + (1.0 - fr) * lost_t


def _transmission_horizon(slopes, wi, phi, psi_end, eta) -> np.ndarray:
    """psi where the refracted direction reaches the horizon (psi_end if it does not before),
    by bisection per azimuth."""
    def below(psi):
        m = _slope_normals(slopes, psi, phi)
        c = np.clip(np.sum(wi * m, axis=-1), 0.0, 1.0)
        return _refracted(wi, m, c, eta)[..., 2] < 0.0

    lo, hi = np.zeros_like(psi_end), psi_end.copy()
    crosses = ~below(psi_end)
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        ok = below(mid)
        lo, hi = np.where(ok, mid, lo), np.where(ok, hi, mid)
    return np.where(crosses, hi, psi_end)


def _loss_quadrature(slopes, eta, theta: float, correlated: bool) -> float:
    """Integral over unit-roughness slopes (tan psi, azimuth phi) of the visible-normal density
    times _loss_per_normal, split where normals stop being visible (psi_v) and where the
    reflected (psi_r, closed form) or refracted (bisection) direction meets the horizon; the
    azimuth split where the visibility cut begins (phi = pi/2), y -> -y symmetry used."""
    wi = np.array([np.sin(theta), 0.0, np.cos(theta)])
    x, w = gauss_legendre_unit(AZIMUTH_NODES)
    phi = np.concatenate([0.5 * np.pi * x, 0.5 * np.pi * (1.0 + x)])
    w_phi = np.concatenate([w, w]) * 0.5 * np.pi * 2.0  # both arcs, and phi -> -phi
    kappa = slopes.alpha_x * wi[0] * np.cos(phi)  # s . wi_xy per unit rho
    g = (slopes.alpha_x * np.cos(phi)) ** 2 + (slopes.alpha_y * np.sin(phi)) ** 2
    with np.errstate(divide="ignore"):
        psi_v = np.where(kappa > 0.0, np.arctan(wi[2] / np.where(kappa > 0.0, kappa, 1.0)),
                         0.5 * np.pi)
    psi_r = np.arctan(wi[2] / (kappa + np.sqrt(kappa * kappa + wi[2] ** 2 * g)))
    psi_t = psi_v if eta is None else _transmission_horizon(slopes, wi, phi, psi_v, eta)
    cuts = np.sort(np.stack([np.zeros_like(phi), np.minimum(psi_r, psi_v),
                             np.minimum(psi_t, psi_v), psi_v], axis=-1), axis=-1)
    u, wu = _graded_unit_rule()
    width = np.diff(cuts, axis=-1)  # (phi, stretch)
    psi = cuts[:, :-1, None] + width[..., None] * u
    weight = w_phi[:, None, None] * width[..., None] * wu
    phi_b = np.broadcast_to(phi[:, None, None], psi.shape)
    m = _slope_normals(slopes, psi, phi_b)
    visible = np.maximum(wi[2] - np.tan(psi) * kappa[:, None, None], 0.0)
    density = visible * _radial_density(slopes, psi)
    lost = _loss_per_normal(slopes, wi, m, eta, correlated)
    area = float(slopes.projected_area(wi))
    return float(np.sum(weight * density * lost) / area)


def energy_loss(distribution: str, alpha, eta: float | complex | None, theta: float,
                masking: str = "correlated") -> float:
    """Fraction of the incident energy a single-scattering model loses at incidence theta.

    For a dielectric it is exactly what the random walk adds back (R + T = 1); for a conductor
    it is the F = 1 value, an upper bound of the multiply scattered energy. masking names the
    single-scattering model in use ("correlated" or "separable", as in model.bsdf). eta None (or
    complex) means a mirror (F = 1); a real eta > 0 a dielectric seen from outside.
    Deterministic quadrature of the loss itself (not 1 - energy), so small losses keep their
    relative accuracy (held to 1 % of independent integrals down to 1e-6 in the tests).
    """
    check_masking(masking)
    if not 0.0 <= theta < 0.5 * np.pi:
        raise ValueError(f"theta must lie in [0, pi/2) radians, got {theta!r}")
    slopes = walkable(make_distribution(distribution, alpha))
    if eta is not None and not np.iscomplexobj(eta):
        eta = float(eta)
    else:
        eta = None
    return _loss_quadrature(slopes, eta, float(theta), masking == "correlated")


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
