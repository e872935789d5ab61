"""Compiled next-event estimation from many walk events towards many directions (numba).

Walker._next_event_all (numpy) is the reference; this kernel repeats micro.py's phase
functions and the walk's escape probability per (event, target) pair, in the same order, for
dielectric and conductor facets on GGX or Beckmann slopes. It is what makes HigherOrderLobe's
tables cheap: their cost is events x targets of exactly this. Serial on purpose: numba's
parallel loop ran it 8x slower on the shared 2-core machine under load (oversubscription).
"""

from __future__ import annotations

import cmath
import math

import numpy as np

from sim.bsdf import kernels

AVAILABLE = kernels.AVAILABLE

if AVAILABLE:
    from numba import njit

    _cos_lambda, _d, _unit = kernels._cos_lambda, kernels._d, kernels._unit
    _fresnel_toward = kernels._fresnel_toward

    @njit(cache=True, error_model="numpy")
    def _conductor_fresnel(c, n_re, n_im, mirror):
        """sim.bsdf.fresnel.fresnel_conductor for one cosine (mirror: F = 1)."""
        if mirror:
            return 1.0
        n = complex(n_re, n_im)
        n2 = n * n
        n2m1 = (n - 1.0) * (n + 1.0)
        root = cmath.sqrt(n2m1 + c * c)
        den_s = c + root
        den_p = n2 * c + root
        if den_s == 0 or den_p == 0:
            return 1.0
        if n2m1 == 0:
            return 0.0
        rs = -n2m1 / den_s / den_s
        rp = n2m1 * ((n2 + 1.0) * c * c - 1.0) / den_p / den_p
        return 0.5 * (abs(rs) ** 2 + abs(rp) ** 2)

    @njit(cache=True, error_model="numpy")
    def _escape(dist, ax, ay, x, y, z, log_u):
        """G1 = u^Lambda of leaving along the upward (x, y, z) from log C1 = log_u."""
        if z <= 0.0:
            return 0.0
        lam = _cos_lambda(dist, ax, ay, x, y, z) / z
        if lam == 0.0:
            return 1.0
        g = math.exp(lam * log_u)
        return g if math.isfinite(g) else 0.0

    @njit(cache=True, error_model="numpy")
    def next_event_all(dist, ax, ay, conductor, eta, n_re, n_im, mirror, w_in, out, log_here,
                       log_there, targets, result):
        """result[e, t] = phase(w_in[e] -> target t) x its escape probability (walk.py)."""
        for e in range(w_in.shape[0]):
            ix, iy, iz = w_in[e, 0], w_in[e, 1], w_in[e, 2]
            outside = out[e]
            el = eta if outside else 1.0 / eta
            elm1 = eta - 1.0 if outside else 1.0 / eta - 1.0
            area = max(iz, 0.0) + _cos_lambda(dist, ax, ay, ix, iy, iz)
            for t in range(targets.shape[0]):
                tx, ty = targets[t, 0], targets[t, 1]
                tz = targets[t, 2] if outside else -targets[t, 2]
                value = 0.0
                if tz > 0.0:
                    hx, hy, hz = _unit(ix + tx, iy + ty, iz + tz)
                    c = ix * hx + iy * hy + iz * hz
                    if c > 0.0 and hz > 0.0 and area > 0.0:
                        if conductor:
                            f = _conductor_fresnel(c, n_re, n_im, mirror)
                        else:
                            f = _fresnel_toward(c, el, elm1)
                        phase = f * _d(dist, ax, ay, hx, hy, hz) / (4.0 * area)
                        value = phase * _escape(dist, ax, ay, tx, ty, tz, log_here[e])
                elif not conductor:
                    hx, hy, hz = _unit(ix + el * tx, iy + el * ty, iz + el * tz)
                    hx, hy, hz = -hx, -hy, -hz
                    if hz < 0.0:
                        hx, hy, hz = -hx, -hy, -hz
                    ci = ix * hx + iy * hy + iz * hz
                    co = tx * hx + ty * hy + tz * hz
                    if ci > 0.0 and co < 0.0 and hz > 0.0 and area > 0.0:
                        denom = ci + el * co
                        d_visible = ci * _d(dist, ax, ay, hx, hy, hz) / area
                        phase = ((1.0 - _fresnel_toward(ci, el, elm1)) * d_visible * el * el
                                 * abs(co) / (denom * denom))
                        if math.isfinite(phase):
                            value = phase * _escape(dist, ax, ay, tx, ty, -tz, log_there[e])
                result[e, t] = value


def supports(micro) -> bool:
    """True when the kernel covers this micro-BSDF (dielectric or conductor facets)."""
    return AVAILABLE and type(micro).__name__ in ("MicroDielectric", "MicroConductor")


def compiled_next_event_all(slopes, micro, w_in, out, targets, log_here, log_there):
    """Walker._next_event_all by the kernel: (n events, m targets) of phase x escape."""
    conductor = type(micro).__name__ == "MicroConductor"
    eta_c = complex(micro.eta_complex) if conductor and micro.eta_complex is not None else 0j
    result = np.empty((len(w_in), len(targets)))
    next_event_all(kernels.CODES[slopes.name], slopes.alpha_x, slopes.alpha_y, conductor,
                   1.0 if conductor else micro.eta, eta_c.real, eta_c.imag,
                   conductor and micro.eta_complex is None, np.ascontiguousarray(w_in),
                   np.ascontiguousarray(out), np.ascontiguousarray(log_here, dtype=np.float64),
                   np.ascontiguousarray(log_there, dtype=np.float64),
                   np.ascontiguousarray(targets, dtype=np.float64), result)
    return result
