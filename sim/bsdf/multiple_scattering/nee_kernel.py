"""Compiled next-event estimation from many walk events towards many directions (numba).

Walker._next_event_all (numpy) is the reference; this kernel repeats micro.py's phase
functions and the walk's escape probability per (event, target) pair, in the same order, from
the scalar formulas of sim.bsdf.primitives, for dielectric and conductor facets on GGX or
Beckmann slopes. It is what makes HigherOrderLobe's
tables cheap: their cost is events x targets of exactly this. Serial on purpose: numba's
parallel loop ran it 8x slower on the shared 2-core machine under load (oversubscription).
"""

from __future__ import annotations

import math

import numpy as np

from sim.bsdf.distributions import Distribution
from sim.bsdf.multiple_scattering.micro import MicroConductor, MicroDielectric
from sim.bsdf.primitives import (
    COMPILED,
    conductor_fresnel,
    cos_lambda,
    fresnel_toward,
    normal_density,
    unit,
)

AVAILABLE = COMPILED

if AVAILABLE:
    from numba import njit

    @njit(cache=True, error_model="numpy")
    def _escape(ndf, ax, ay, x, y, z, log_u):
        """G1 = u^Lambda of leaving along the upward (x, y, z) from log C1 = log_u."""
        if z <= 0.0:
            return 0.0
        lam = cos_lambda(ndf, ax, ay, x, y, z) / z
        if lam == 0.0:
            return 1.0
        g = math.exp(lam * log_u)
        return g if math.isfinite(g) else 0.0

    @njit(cache=True, error_model="numpy")
    def next_event_all(ndf, ax, ay, conductor, eta, has_f, n_c, w_in, out, log_here,
                       log_there, targets, result):
        """result[e, t] = phase(w_in[e] -> target t) x its escape probability (walk.py)."""
        for e in range(w_in.shape[0]):
            ix, iy, iz = w_in[e, 0], w_in[e, 1], w_in[e, 2]
            outside = out[e]
            el = eta if outside else 1.0 / eta
            elm1 = eta - 1.0 if outside else 1.0 / eta - 1.0
            area = max(iz, 0.0) + cos_lambda(ndf, ax, ay, ix, iy, iz)
            for t in range(targets.shape[0]):
                tx, ty = targets[t, 0], targets[t, 1]
                tz = targets[t, 2] if outside else -targets[t, 2]
                value = 0.0
                if tz > 0.0:
                    hx, hy, hz = unit(ix + tx, iy + ty, iz + tz)
                    c = ix * hx + iy * hy + iz * hz
                    if c > 0.0 and hz > 0.0 and area > 0.0:
                        if conductor:
                            f = conductor_fresnel(c, has_f, n_c)
                        else:
                            f = fresnel_toward(c, el, elm1)
                        phase = f * normal_density(ndf, ax, ay, hx, hy, hz) / (4.0 * area)
                        value = phase * _escape(ndf, ax, ay, tx, ty, tz, log_here[e])
                elif not conductor:
                    hx, hy, hz = unit(ix + el * tx, iy + el * ty, iz + el * tz)
                    hx, hy, hz = -hx, -hy, -hz
                    if hz < 0.0:
                        hx, hy, hz = -hx, -hy, -hz
                    ci = ix * hx + iy * hy + iz * hz
                    co = tx * hx + ty * hy + tz * hz
                    if ci > 0.0 and co < 0.0 and hz > 0.0 and area > 0.0:
                        denom = ci + el * co
                        d_visible = ci * normal_density(ndf, ax, ay, hx, hy, hz) / area
                        phase = ((1.0 - fresnel_toward(ci, el, elm1)) * d_visible * el * el
                                 * abs(co) / (denom * denom))
                        if math.isfinite(phase):
                            value = phase * _escape(ndf, ax, ay, tx, ty, -tz, log_there[e])
                result[e, t] = value


def supports(slopes: Distribution, micro) -> bool:
    """True when the kernel covers this walk: dielectric or conductor facets on slopes that
    have scalar formulas (Distribution.kernel)."""
    return (AVAILABLE and slopes.kernel is not None
            and isinstance(micro, (MicroDielectric, MicroConductor)))


def compiled_next_event_all(slopes: Distribution, micro, w_in, out, targets, log_here,
                            log_there) -> np.ndarray:
    """Walker._next_event_all by the kernel: (n events, m targets) of phase x escape."""
    conductor = isinstance(micro, MicroConductor)
    has_f = conductor and micro.eta_complex is not None
    result = np.empty((len(w_in), len(targets)))
    next_event_all(int(slopes.kernel), float(slopes.alpha_x), float(slopes.alpha_y), conductor,
                   1.0 if conductor else micro.eta, has_f,
                   complex(micro.eta_complex) if has_f else 0j, np.ascontiguousarray(w_in),
                   np.ascontiguousarray(out), np.ascontiguousarray(log_here, dtype=np.float64),
                   np.ascontiguousarray(log_there, dtype=np.float64),
                   np.ascontiguousarray(targets, dtype=np.float64), result)
    return result
