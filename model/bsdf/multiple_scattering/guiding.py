"""Next-direction sampling guided towards wo, for evaluating walks (one-sample MIS).

Next-event estimation at event k+1 is large when the arriving direction meets wo through the
peak of the facet distribution; plain phase sampling at event k finds those directions rarely
when alpha is small, which makes the estimate heavy-tailed. Here the direction leaving event k
is drawn from the phase function, or (a share BACKWARDS of the time) "backwards from wo": a
facet normal m is drawn from the normals visible from wo (or from -wo for a transmitted wo) on the
side of the next event, and the arriving direction that m sends into wo is built (mirror or
reverse Snell). The walk weight is multiplied by phase / (mixture density), so the estimate
stays unbiased and the multiplier is at most 1 / (1 - BACKWARDS).
"""

from __future__ import annotations

import numpy as np

from model.bsdf.distributions import Distribution
from model.bsdf.vectors import dot

#: Share of next directions drawn backwards from wo (the rest from the phase function).
BACKWARDS = 0.25


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return v / n


def _flip(w: np.ndarray) -> np.ndarray:
    return w * np.array([1.0, 1.0, -1.0])


def refract(v: np.ndarray, n: np.ndarray, eta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Direction transmitted from v (pointing away on n's side, v.n > 0) through a facet n into
    a medium eta times denser; False where total internal reflection forbids it."""
    c = dot(v, n)
    sin2_t = (1.0 - c * c) / (eta * eta)
    ok = (sin2_t < 1.0) & (c > 0.0)
    cos_t = np.sqrt(np.maximum(0.0, 1.0 - sin2_t))
    t = -v / eta[..., None] + (c / eta - cos_t)[..., None] * n
    return _unit(t), ok


def adjoint_density(slopes: Distribution, w_in: np.ndarray, wo: np.ndarray,
                    eta: np.ndarray) -> np.ndarray:
    """Density over w_in of the backwards-from-wo proposal (local frame of the next event).

    wo above (same side): m ~ D_visible(wo), w_in = mirror of wo, density D(h) / (4 A(wo)).
    wo below (across the interface, eta = n_other / n_this): m ~ D_visible(-wo), w_in refracted
    backwards, density D_visible(-wo, h) |<w_in,h>| / (<w_in,h> + eta <wo,h>)^2.
    """
    above = wo[..., 2] > 0.0
    out = np.zeros(w_in.shape[:-1])
    if above.any():
        wi_, wo_ = w_in[above], wo[above]
        h = _unit(wi_ + wo_)
        area = slopes.projected_area(wo_)
        ok = (h[..., 2] > 0.0) & (dot(wo_, h) > 0.0) & (area > 0.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            out[above] = np.where(ok, slopes.D(h) / (4.0 * area), 0.0)
    below = ~above
    if below.any():
        wi_, wo_, e = w_in[below], wo[below], eta[below]
        h = -_unit(wi_ + e[..., None] * wo_)
        h = h * np.where(h[..., 2] < 0.0, -1.0, 1.0)[..., None]
        ci, co = dot(wi_, h), dot(wo_, h)
        ok = (ci > 0.0) & (co < 0.0) & (h[..., 2] > 0.0)
        denom = ci + e * co
        with np.errstate(divide="ignore", invalid="ignore"):
            value = slopes.D_visible(-wo_, h) * ci / (denom * denom)
        out[below] = np.where(ok & np.isfinite(value), value, 0.0)
    return out


def sample_adjoint(slopes: Distribution, wo: np.ndarray, eta: np.ndarray,
                   u1: np.ndarray, u2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """An arriving direction w_in drawn backwards from wo (see adjoint_density); validity."""
    above = wo[..., 2] > 0.0
    view = np.where(above[..., None], wo, -wo)
    m = slopes.sample_visible_sphere(view, u1, u2)
    mirrored = 2.0 * dot(wo, m)[..., None] * m - wo
    back, ok_t = refract(wo, -m, 1.0 / eta)
    w_in = np.where(above[..., None], mirrored, back)
    ok = np.where(above, dot(wo, m) > 0.0, ok_t)
    return w_in, ok & np.all(np.isfinite(w_in), axis=-1)


def guided_scatter(slopes, micro, w_in, m, out, wo, u, unit, phase_sample):
    """Next direction at an event: (direction in this side's frame, weight factor, crossed).

    phase_sample = (w_next, factor, crossed) already drawn from the phase function with the
    normal m; u (4, n) uniforms: strategy, target side, and the backwards normal. Conductor
    and dielectric facets only (their phase functions are known in closed form).
    """
    w_p, _, crossed_p = phase_sample
    transmits = micro.transmits
    target_cross = (u[1] < 0.5) if transmits else np.zeros(out.shape, dtype=bool)
    side = out ^ target_cross
    wo_side = np.where(side[:, None], wo, _flip(wo))  # wo in the frame of the next event
    eta_side = micro.local_eta(side)
    arriving, ok_a = sample_adjoint(slopes, wo_side, eta_side, u[2], u[3])
    leaving = -arriving  # travel direction in the next event's frame
    w_a = np.where(target_cross[:, None], _flip(leaving), leaving)
    use_adj = (u[0] < BACKWARDS) & ok_a
    crossed = np.where(use_adj, target_cross, crossed_p)
    w_next = np.where(use_adj[:, None], w_a, w_p)
    # densities of the chosen (crossed, w_next) under both strategies
    p_phase = np.zeros(out.shape)
    p_energy = np.zeros(out.shape)
    refl = ~crossed
    if refl.any():
        p_phase[refl] = micro.phase_reflect(slopes, w_in[refl], w_next[refl], out[refl],
                                            m[refl], True)
        p_energy[refl] = micro.phase_reflect(slopes, w_in[refl], w_next[refl], out[refl],
                                             m[refl], unit)
    if crossed.any():
        p_phase[crossed] = micro.phase_transmit(slopes, w_in[crossed], w_next[crossed],
                                                out[crossed], True)
        p_energy[crossed] = p_phase[crossed]
    next_side = out ^ crossed
    wo_next = np.where(next_side[:, None], wo, _flip(wo))
    arriving_next = -np.where(crossed[:, None], _flip(w_next), w_next)
    p_adj = adjoint_density(slopes, arriving_next, wo_next, micro.local_eta(next_side))
    p_adj = p_adj * (0.5 if transmits else 1.0)
    mixture = (1.0 - BACKWARDS) * p_phase + BACKWARDS * p_adj
    with np.errstate(divide="ignore", invalid="ignore"):
        factor = np.where(mixture > 0.0, p_energy / mixture, 0.0)
    # a failed backwards draw (total internal reflection) ends the walk: the mixture density
    # above counts only the successful draws, so this keeps the estimate unbiased
    factor = np.where((u[0] < BACKWARDS) & ~ok_a, 0.0, factor)
    return w_next, factor, crossed
