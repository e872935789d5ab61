"""Energy of the microsurface: what single scattering misses, and directional albedo by Monte Carlo.

energy_loss is deterministic: a quadrature, over the facets' slopes, of what each facet's single
scattering loses, split wherever the loss has a kink or a jump (visibility, the scattered
directions' horizons, total internal reflection), graded towards every split and adaptive in
the azimuth; within 1e-6 relative of independent integrals down to losses of 1e-7, cheap
enough for the bench to decide whether multiple scattering is worth computing.
albedo_estimate integrates any model's f |cos o| over the sphere by importance sampling, the
white-furnace check of the random walk.
"""

from __future__ import annotations

import numpy as np

from model.bsdf.distributions import make_distribution
from model.bsdf.fresnel import dielectric_reflectance_transmittance
from model.bsdf.masking import check_masking, log_beta
from model.bsdf.multiple_scattering.walk import flip, walkable

#: Gauss-Legendre nodes per panel, how many times and by what ratio the panels shrink towards
#: each end of a stretch between breakpoints, and stretches of the facets' tilt (0 to pi/2)
#: split apart.
PANEL_NODES = 5
GRADING = 10
GRADING_RATIO = 0.4
ARC_PANELS = 6
#: Azimuth: relative tolerance of the adaptive Gauss-Kronrod rule, the most halvings of a
#: panel, and breakpoints about phi = pi/2 in units of the grazing visibility scale (those
#: below GRAZING_WIDEST radians).
TOLERANCE = 1e-6
MAX_HALVINGS = 12
GRAZING_SCALES = np.array([0.25, 1.0, 4.0])
GRAZING_WIDEST = 0.5
#: The 15-point Gauss-Kronrod rule on [-1, 1] (QUADPACK's qk15): nodes >= 0 descending, their
#: weights, and the weights of the embedded 7-point Gauss rule at the odd-numbered nodes.
KRONROD_NODES = np.array([
    0.991455371120812639206854697526329, 0.949107912342758524526189684047851,
    0.864864423359769072789712788640926, 0.741531185599394439863864773280788,
    0.586087235467691130294144845693013, 0.405845151377397166906606412076961,
    0.207784955007898467600689403773245, 0.0])
KRONROD_WEIGHTS = np.array([
    0.022935322010529224963732008058970, 0.063092092629978553290700663189204,
    0.104790010322250183839876322541518, 0.140653259715525918745189590510238,
    0.169004726639267902826583426598550, 0.190350578064785409913256402421014,
    0.204432940075298892414161999234649, 0.209482141084727828012999174891714])
GAUSS_WEIGHTS = np.array([
    0.129484966168869693270611432679082, 0.279705391489276667901467771423780,
    0.381830050505118944950369775488975, 0.417959183673469387755102040816327])
#: Scan points and bisections that find where the refracted direction crosses the horizon.
HORIZON_SCAN = 16
BISECTIONS = 50


def gauss_legendre_unit(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Nodes and weights of n-point Gauss-Legendre on [0, 1]."""
    x, w = np.polynomial.legendre.leggauss(n)
    return 0.5 * (x + 1.0), 0.5 * w


def _graded_unit_rule() -> tuple[np.ndarray, np.ndarray]:
    """Nodes and weights on [0, 1]: PANEL_NODES-point panels shrinking by GRADING_RATIO towards
    both ends GRADING times, so a stretch resolves what happens near a breakpoint (the loss's
    square-root and 1/elevation^2 behaviour at total internal reflection and the horizons)."""
    edges = 0.5 * GRADING_RATIO ** np.arange(GRADING + 1)
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


def _arc_to_psi(s: np.ndarray, root_g: np.ndarray) -> np.ndarray:
    """psi of the unit-roughness slope whose normal is tilted s (radians, clipped to [0, pi/2])
    from the mean normal along an azimuth whose slope stretch is root_g."""
    s = np.clip(s, 0.0, 0.5 * np.pi)
    with np.errstate(over="ignore"):
        return np.arctan2(np.sin(s), root_g * np.cos(s))


def _transmission_horizons(wi_z, r, s0, lo, hi, eta) -> np.ndarray:
    """(phi, 2): the first and last tilt s in [lo, hi] (where light refracts) at which the
    refracted direction crosses the horizon, found on a scan and refined by bisection (hi if
    none). Along the azimuth's great circle wi . m = r cos(s - s0) and m_z = cos s, so the
    refracted z has the sign of (c - sqrt(eta^2 - 1 + c^2)) cos s - wi_z."""
    def below(s):
        c = r[:, None] * np.cos(s - s0[:, None])
        return (c - np.sqrt(np.maximum(eta * eta - 1.0 + c * c, 0.0))) * np.cos(s) < wi_z

    grid = lo[:, None] + (hi - lo)[:, None] * np.linspace(0.0, 1.0, HORIZON_SCAN + 1)
    side = below(grid)
    change = side[:, 1:] != side[:, :-1]
    found = change.any(axis=1)
    roots = []
    for k in (np.argmax(change, axis=1), HORIZON_SCAN - 1 - np.argmax(change[:, ::-1], axis=1)):
        a = np.take_along_axis(grid, k[:, None], 1)
        b = np.take_along_axis(grid, k[:, None] + 1, 1)
        side_a = np.take_along_axis(side, k[:, None], 1)
        for _ in range(BISECTIONS):
            mid = 0.5 * (a + b)
            same = below(mid) == side_a
            a, b = np.where(same, mid, a), np.where(same, b, mid)
        roots.append(np.where(found, 0.5 * (a + b)[:, 0], hi))
    return np.stack(roots, axis=-1)


def _psi_cuts(slopes, wi, phi, eta) -> np.ndarray:
    """(phi, cut) sorted psi breakpoints per azimuth: 0, the end of visibility psi_v, the
    reflected direction's horizon, the edges of total internal reflection, the refracted
    direction's horizons, and normals tilted k pi / (2 ARC_PANELS) (the loss varies on the
    scale of tilts, which small alpha squeezes towards psi = pi/2)."""
    root_g = np.sqrt((slopes.alpha_x * np.cos(phi)) ** 2 + (slopes.alpha_y * np.sin(phi)) ** 2)
    # along an azimuth the normal turns on a great circle: wi . m = r cos(s - s0), s its tilt
    s0 = np.arctan2(-slopes.alpha_x * wi[0] * np.cos(phi) / root_g, wi[2])
    r = np.hypot(wi[2], wi[0] * slopes.alpha_x * np.cos(phi) / root_g)
    s_v = np.minimum(s0 + 0.5 * np.pi, 0.5 * np.pi)
    psi_v = _arc_to_psi(s_v, root_g)
    kappa = slopes.alpha_x * wi[0] * np.cos(phi)
    psi_r = np.arctan(wi[2] / (kappa + np.sqrt(kappa * kappa + wi[2] ** 2 * root_g**2)))
    tilts = np.arange(1, ARC_PANELS) * 0.5 * np.pi / ARC_PANELS
    cuts = [np.zeros_like(phi), psi_r, psi_v, *(_arc_to_psi(t, root_g) for t in tilts)]
    if eta is not None:
        lo, hi = np.zeros_like(phi), s_v
        if eta < 1.0:  # refraction only where wi . m exceeds the critical cosine
            spread = np.arccos(np.minimum(np.sqrt(1.0 - eta * eta) / r, 1.0))
            lo = np.clip(s0 - spread, 0.0, s_v)
            hi = np.clip(s0 + spread, 0.0, s_v)
            cuts += [_arc_to_psi(lo, root_g), _arc_to_psi(hi, root_g)]
        horizons = _transmission_horizons(wi[2], r, s0, lo, hi, eta)
        cuts += [_arc_to_psi(h, root_g) for h in horizons.T]
    return np.sort(np.minimum(np.stack(cuts, axis=-1), psi_v[:, None]), axis=-1)


def _critical_azimuths(slopes, wi, eta) -> np.ndarray:
    """Azimuths in (0, pi) where a stretch of refracting normals appears beyond the critical
    angle (wi . m reaches the critical cosine at most), where the psi integral has a kink."""
    if eta is None or eta >= 1.0 or wi[0] == 0.0:
        return np.empty(0)
    # max over the azimuth's normals of (wi . m)^2 = wi_z^2 + wi_x^2 q, q = cos^2 of the azimuth
    # in the stretched slope frame; solved for q at the critical cosine
    q = (1.0 - eta * eta - wi[2] ** 2) / wi[0] ** 2
    if not 0.0 < q < 1.0:
        return np.empty(0)
    phi = np.arctan(slopes.alpha_x / slopes.alpha_y * np.sqrt((1.0 - q) / q))
    return np.array([phi, np.pi - phi])


def _azimuth_integrand(slopes, wi, phi, eta, correlated: bool) -> np.ndarray:
    """Integral over psi, at each azimuth phi, of the visible-normal density times
    _loss_per_normal: graded Gauss-Legendre panels on every stretch between _psi_cuts."""
    cuts = _psi_cuts(slopes, wi, phi, eta)
    u, wu = _graded_unit_rule()
    width = np.diff(cuts, axis=-1)
    psi = cuts[:, :-1, None] + width[..., None] * u
    weight = width[..., None] * wu
    phi_b = np.broadcast_to(phi[:, None, None], psi.shape)
    m = _slope_normals(slopes, psi, phi_b)
    kappa = slopes.alpha_x * wi[0] * np.cos(phi)
    visible = np.maximum(wi[2] - np.tan(psi) * kappa[:, None, None], 0.0)
    density = visible * _radial_density(slopes, psi)
    lost = _loss_per_normal(slopes, wi, m, eta, correlated)
    return np.sum(weight * density * lost, axis=(1, 2))


def _kronrod_rule() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Nodes on [0, 1] of the 15-point Gauss-Kronrod rule, its weights, and the weights of the
    embedded 7-point Gauss rule on the same nodes (zero on the Kronrod-only nodes)."""
    x = np.concatenate([-KRONROD_NODES[:-1], KRONROD_NODES[::-1]])
    w = np.concatenate([KRONROD_WEIGHTS[:-1], KRONROD_WEIGHTS[::-1]])
    gauss = np.zeros(8)
    gauss[1::2] = GAUSS_WEIGHTS
    g = np.concatenate([gauss[:-1], gauss[::-1]])
    return 0.5 * (x + 1.0), 0.5 * w, 0.5 * g


def _azimuth_panels(slopes, wi, eta) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Initial azimuth panels over [0, pi] as maps phi = origin + span u^power, u in [0, 1]:
    split at pi/2, about it at grazing incidence (the visible normals change within
    ~cot(theta) / alpha of it) and at the critical azimuths, whose square-root kink the
    quadratic map (power 2 from the kink) smooths."""
    spread = np.empty(0)
    if wi[0] > 0.0:
        spread = np.arctan(wi[2] / (wi[0] * slopes.alpha_x) * GRAZING_SCALES)
        spread = spread[spread < GRAZING_WIDEST]
    critical = _critical_azimuths(slopes, wi, eta)
    edges = np.unique(np.concatenate([[0.0, 0.5 * np.pi, np.pi], 0.5 * np.pi - spread,
                                      0.5 * np.pi + spread, critical]))
    a, b = edges[:-1], edges[1:]
    from_b = np.isin(b, critical) & ~np.isin(a, critical)
    kink = np.isin(a, critical) | from_b
    origin = np.where(from_b, b, a)
    return origin, np.where(from_b, a - b, b - a), np.where(kink, 2.0, 1.0)


def _loss_quadrature(slopes, eta, theta: float, correlated: bool) -> float:
    """Integral over unit-roughness slopes (tan psi, azimuth phi) of the visible-normal density
    times _loss_per_normal / projected area: in psi _azimuth_integrand; in phi adaptive
    Gauss-Kronrod 7-15 on _azimuth_panels, a panel halved until its Kronrod-Gauss difference
    is below TOLERANCE of the total in proportion to its width, the y -> -y symmetry used."""
    wi = np.array([np.sin(theta), 0.0, np.cos(theta)])
    x, w_kronrod, w_gauss = _kronrod_rule()
    origin, span, power = _azimuth_panels(slopes, wi, eta)
    lo, width = np.zeros_like(span), np.ones_like(span)
    accepted = 0.0
    for _ in range(MAX_HALVINGS):
        u = lo[:, None] + width[:, None] * x
        phi = origin[:, None] + span[:, None] * u ** power[:, None]
        jacobian = np.abs(span)[:, None] * power[:, None] * u ** (power[:, None] - 1.0)
        values = _azimuth_integrand(slopes, wi, phi.ravel(), eta, correlated).reshape(u.shape)
        values = values * jacobian
        kronrod, gauss = width * (values @ w_kronrod), width * (values @ w_gauss)
        total = accepted + float(np.sum(kronrod))
        share = np.abs(span) * width / np.pi
        done = np.abs(kronrod - gauss) <= TOLERANCE * abs(total) * share
        accepted += float(np.sum(kronrod[done]))
        if done.all():
            break
        keep = ~done
        lo, width, origin, span, power = (lo[keep], 0.5 * width[keep], origin[keep], span[keep],
                                          power[keep])
        lo, width = np.concatenate([lo, lo + width]), np.tile(width, 2)
        origin, span, power = np.tile(origin, 2), np.tile(span, 2), np.tile(power, 2)
    return 2.0 * total / float(slopes.projected_area(wi))


def energy_loss(distribution: str, alpha, eta: float | complex | None, theta: float,
                masking: str = "correlated") -> float:
    """Fraction of the incident energy a single-scattering model loses at incidence theta.

    For a dielectric it is exactly what the random walk adds back (R + T = 1); for a conductor
    it is the F = 1 value, an upper bound of the multiply scattered energy. masking names the
    single-scattering model in use ("correlated" or "separable", as in model.bsdf). eta None (or
    complex) means a mirror (F = 1); a real eta > 0 a dielectric of relative index eta (the
    index beyond the surface over that of wi's side: eta < 1 is light inside glass, with total
    internal reflection). Deterministic quadrature of the loss itself (not 1 - energy), so
    small losses keep their relative accuracy: within 1e-6 relative of an independent adaptive
    integral for losses >= 1e-7 (and 1e-13 absolute below) over eta 1.51, 1/1.51 and mirrors,
    alpha 1e-3 to 1.0, theta 0 to 89 deg, Beckmann and GGX (bench/energy_loss_accuracy.py).
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
