"""Compiled phase functions and next-event estimation of the random walk (numba).

micro.py's phase functions and Walker's escape probability, one event and one direction at a
time, from the scalar formulas of model.bsdf.primitives, for dielectric and conductor facets on
GGX or Beckmann slopes; Walker.next_event_all (numpy) is their reference. walk_kernel.py walks
with them, and next_event_all scores many events towards many directions, which is what makes
HigherOrderLobe's tables cheap. Serial on purpose: numba's parallel loop ran 8x slower on the
shared 2-core machine under load (oversubscription); keyed.py runs whole batches of walks on
a few threads instead, within numba's thread count for the calling thread.

A surface travels as one Surface record (surface() builds it from a Walker's slopes and micro-BSDF).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from model.bsdf.distributions import Distribution
from model.bsdf.multiple_scattering.micro import MicroConductor, MicroDielectric
from model.bsdf.primitives import (
    COMPILED,
    conductor_fresnel,
    cos_lambda,
    fresnel_toward,
    inlined,
    normal_density,
    scalar,
    unit,
)

AVAILABLE = COMPILED


class Surface(NamedTuple):
    """A microsurface as the kernels take it: slope kernel (Distribution.kernel) and roughness,
    conductor or dielectric facets, eta = n_interior / n_exterior (dielectric), and the complex
    index n_c of a conductor when has_f (else F = 1, as for any facet in unit mode)."""

    ndf: int
    alpha_x: float
    alpha_y: float
    conductor: bool
    eta: float
    has_f: bool
    n_c: complex


@scalar
def projected_area(s, x, y, z):
    """Integral of <w, m>+ D(m) dm for w anywhere on the sphere (Distribution.projected_area)."""
    return max(z, 0.0) + cos_lambda(s.ndf, s.alpha_x, s.alpha_y, x, y, z)


@scalar
def escape_lambda(lam, log_u):
    """G1 = u^Lambda of leaving, upward, with Smith Lambda lam >= 0, from log C1 = log_u."""
    if lam == 0.0:
        return 1.0
    g = math.exp(lam * log_u)
    return g if math.isfinite(g) else 0.0


@inlined
def escape(s, x, y, z, log_u):
    """G1 = u^Lambda of leaving along (x, y, z) from log C1 = log_u (0 for z <= 0)."""
    if z <= 0.0:
        return 0.0
    return escape_lambda(cos_lambda(s.ndf, s.alpha_x, s.alpha_y, x, y, z) / z, log_u)


@scalar
def unsigned_lambda(s, x, y, z):
    """Lambda of (x, y, |z|): the escape exponent of a direction on either side (inf at z = 0)."""
    c = abs(z)
    return cos_lambda(s.ndf, s.alpha_x, s.alpha_y, x, y, z) / c if c > 0.0 else math.inf


@scalar
def side_eta(eta, outside):
    """(n_other / n_this, that minus 1 without rounding) on the outside or the inside."""
    if outside:
        return eta, eta - 1.0
    return 1.0 / eta, 1.0 / eta - 1.0


@scalar
def facet_fresnel(s, with_f, c, el, elm1):
    """Reflectance of a facet at cosine c: conductor (1 without has_f, or unless with_f) or
    dielectric towards el."""
    if s.conductor:
        return conductor_fresnel(c, s.has_f and with_f, s.n_c)
    return fresnel_toward(c, el, elm1)


@inlined
def reflect_density(s, ix, iy, iz, area, ox, oy, oz):
    """(D(h) / (4 A(w_in)), <w_in,h>): the reflected phase function from i (projected area
    `area`) to o without its Fresnel factor, h the mirror facet between them ((0, 0) where none
    reflects i into o)."""
    hx, hy, hz = unit(ix + ox, iy + oy, iz + oz)
    c = ix * hx + iy * hy + iz * hz
    if not (c > 0.0 and hz > 0.0 and area > 0.0):
        return 0.0, 0.0
    return normal_density(s.ndf, s.alpha_x, s.alpha_y, hx, hy, hz) / (4.0 * area), c


@inlined
def phase_reflect(s, with_f, el, elm1, ix, iy, iz, area, ox, oy, oz):
    """F(<w_in,h>) D(h) / (4 A(w_in)) (micro._reflect_phase), w_in = i of projected area
    `area`, w_out = o; a conductor's F only with_f (facet_fresnel)."""
    density, c = reflect_density(s, ix, iy, iz, area, ox, oy, oz)
    if not density > 0.0:
        return 0.0
    return facet_fresnel(s, with_f, c, el, elm1) * density


@scalar
def refraction_normal(ix, iy, iz, ox, oy, oz, el):
    """(h, <i,h>, <o,h>) of the facet h (h_z >= 0) that refracts i into o below it, el the
    relative index across it: h = -(i + el o) / |.| turned upward."""
    hx, hy, hz = unit(ix + el * ox, iy + el * oy, iz + el * oz)
    if hz <= 0.0:
        hx, hy, hz = -hx, -hy, -hz
    return (hx, hy, hz, ix * hx + iy * hy + iz * hz, ox * hx + oy * hy + oz * hz)


@inlined
def transmit_density(s, el, ix, iy, iz, area, ox, oy, oz):
    """(D_visible(w_in,h) el^2 |<w_out,h>| / (<w_in,h> + el <w_out,h>)^2, <w_in,h>): the
    transmitted phase function from i (projected area `area`) to o below without its (1 - F)
    ((0, 0) where no facet refracts i into o)."""
    hx, hy, hz, ci, co = refraction_normal(ix, iy, iz, ox, oy, oz, el)
    if not (ci > 0.0 and co < 0.0 and hz > 0.0 and area > 0.0):
        return 0.0, 0.0
    denom = ci + el * co
    d_visible = ci * normal_density(s.ndf, s.alpha_x, s.alpha_y, hx, hy, hz) / area
    return d_visible * el * el * abs(co) / (denom * denom), ci


@inlined
def phase_transmit(s, el, elm1, ix, iy, iz, area, ox, oy, oz):
    """(1-F) D_visible(w_in,h) el^2 |<w_out,h>| / (<w_in,h> + el <w_out,h>)^2, w_out below
    (MicroDielectric.phase_transmit); area is w_in's projected area."""
    density, c = transmit_density(s, el, ix, iy, iz, area, ox, oy, oz)
    value = (1.0 - fresnel_toward(c, el, elm1)) * density if density > 0.0 else 0.0
    return value if math.isfinite(value) else 0.0


@inlined
def next_event(s, outside, ix, iy, iz, area, tx, ty, tz, lam_t, log_here, log_there):
    """Phase function from w_in = i (projected area `area`) towards the world direction t
    (unsigned_lambda lam_t) times t's escape probability from this event
    (Walker._next_event)."""
    el, elm1 = side_eta(s.eta, outside)
    lz = tz if outside else -tz  # t in the local frame of this side
    if lz > 0.0:
        phase = phase_reflect(s, True, el, elm1, ix, iy, iz, area, tx, ty, lz)
        return phase * escape_lambda(lam_t, log_here) if phase > 0.0 else 0.0
    if s.conductor:
        return 0.0
    phase = phase_transmit(s, el, elm1, ix, iy, iz, area, tx, ty, lz)
    return phase * escape_lambda(lam_t, log_there) if phase > 0.0 else 0.0


@scalar
def target_lambdas(s, targets):
    """unsigned_lambda of every target (m, 3): computed once, used at every event."""
    lam = np.empty(targets.shape[0])
    for t in range(targets.shape[0]):
        lam[t] = unsigned_lambda(s, targets[t, 0], targets[t, 1], targets[t, 2])
    return lam


@scalar
def next_event_all(s, w_in, out, log_here, log_there, targets, result):
    """result[e, t] = phase(w_in[e] -> target t) x its escape probability (walk.py)."""
    lam = target_lambdas(s, targets)
    for e in range(w_in.shape[0]):
        ix, iy, iz = w_in[e, 0], w_in[e, 1], w_in[e, 2]
        area = projected_area(s, ix, iy, iz)
        for t in range(targets.shape[0]):
            result[e, t] = next_event(s, out[e], ix, iy, iz, area, targets[t, 0], targets[t, 1],
                                      targets[t, 2], lam[t], log_here[e], log_there[e])


def supports(slopes: Distribution, micro) -> bool:
    """True when the kernels cover this walk: dielectric or conductor facets on slopes that
    have scalar formulas (Distribution.kernel)."""
    return (AVAILABLE and slopes.kernel is not None
            and isinstance(micro, (MicroDielectric, MicroConductor)))


def surface(slopes: Distribution, micro, unit_mode: bool = False) -> Surface:
    """The Surface of a supported walk; unit_mode drops the conductor's Fresnel factor (the
    walk's direction density)."""
    conductor = isinstance(micro, MicroConductor)
    has_f = conductor and micro.eta_complex is not None and not unit_mode
    return Surface(int(slopes.kernel), float(slopes.alpha_x), float(slopes.alpha_y), conductor,
                   1.0 if conductor else float(micro.eta), has_f,
                   complex(micro.eta_complex) if has_f else 0j)


def compiled_next_event_all(slopes: Distribution, micro, w_in, out, targets, log_here,
                            log_there, unit_mode: bool = False) -> np.ndarray:
    """Walker.next_event_all by the kernel: (n events, m targets) of phase x escape."""
    result = np.empty((len(w_in), len(targets)))
    next_event_all(surface(slopes, micro, unit_mode), np.ascontiguousarray(w_in),
                   np.ascontiguousarray(out), np.ascontiguousarray(log_here, dtype=np.float64),
                   np.ascontiguousarray(log_there, dtype=np.float64),
                   np.ascontiguousarray(targets, dtype=np.float64), result)
    return result
