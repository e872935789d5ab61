"""The guided proposal of guiding.py compiled (numba), one event at a time, for walk_kernel.

An evaluating walk draws its next direction from the phase function or, with probability
BACKWARDS, backwards from wo (a normal visible from wo on the side of the next event and the
arriving direction it mirrors or refracts into wo), and weighs it by one-sample MIS of the two.
"""

from __future__ import annotations

import math

from model.bsdf.multiple_scattering.guiding import BACKWARDS
from model.bsdf.multiple_scattering.nee_kernel import (
    phase_reflect,
    phase_transmit,
    refraction_normal,
    side_eta,
)
from model.bsdf.multiple_scattering.visible_kernel import visible_normal
from model.bsdf.primitives import inlined, normal_density, unit


@inlined
def adjoint_density(s, ix, iy, iz, ox, oy, oz, area, eta):
    """Density over w_in = i of the backwards-from-wo proposal (guiding.adjoint_density);
    area: projected_area of wo (above) or of -wo (below), |o_z| + cos_lambda(o) either way."""
    if oz > 0.0:
        hx, hy, hz = unit(ix + ox, iy + oy, iz + oz)
        if hz > 0.0 and ox * hx + oy * hy + oz * hz > 0.0 and area > 0.0:
            return normal_density(s.ndf, s.alpha_x, s.alpha_y, hx, hy, hz) / (4.0 * area)
        return 0.0
    hx, hy, hz, ci, co = refraction_normal(ix, iy, iz, ox, oy, oz, eta)
    if not (ci > 0.0 and co < 0.0 and hz > 0.0 and area > 0.0):
        return 0.0
    denom = ci + eta * co  # D_visible(-o, h) = -co D(h) / area
    value = (-co * normal_density(s.ndf, s.alpha_x, s.alpha_y, hx, hy, hz) / area * ci
             / (denom * denom))
    return value if math.isfinite(value) else 0.0


@inlined
def sample_adjoint(s, ox, oy, oz, eta, u1, u2):
    """An arriving direction drawn backwards from wo (guiding.sample_adjoint): (x, y, z, ok)."""
    above = oz > 0.0
    sign = 1.0 if above else -1.0
    mx, my, mz = visible_normal(s, sign * ox, sign * oy, sign * oz, u1, u2)
    c = ox * mx + oy * my + oz * mz
    if above:
        x, y, z = 2.0 * c * mx - ox, 2.0 * c * my - oy, 2.0 * c * mz - oz
        ok = c > 0.0
    else:  # refract wo through the facet -m into a medium 1/eta times denser
        e = 1.0 / eta
        cn = -c
        sin2 = (1.0 - cn * cn) / (e * e)
        ok = sin2 < 1.0 and cn > 0.0
        k = cn / e - math.sqrt(max(0.0, 1.0 - sin2))
        x, y, z = unit(-ox / e - k * mx, -oy / e - k * my, -oz / e - k * mz)
    return x, y, z, ok and math.isfinite(x) and math.isfinite(y) and math.isfinite(z)


@inlined
def sample_backwards(s, outside, ox, oy, oz, u1, u2, u3):
    """The guided proposal's backwards-from-wo draw (guiding.guided_scatter): a next direction
    in this side's frame whose arrival at the next event m sends into wo, the next event on
    the far side when u1 < 1/2 (dielectric): (x, y, z, crossed, ok)."""
    crossed = (not s.conductor) and u1 < 0.5
    side = outside != crossed
    e_side = side_eta(s.eta, side)[0] if not s.conductor else 1.0
    bx, by, bz, ok = sample_adjoint(s, ox, oy, oz if side else -oz, e_side, u2, u3)
    return -bx, -by, (bz if crossed else -bz), crossed, ok  # travel along minus the arrival


@inlined
def mixture_weight(s, outside, ix, iy, iz, area, guide, wx, wy, wz, crossed):
    """The walk's weight factor for next direction w however drawn, by one-sample MIS of the
    phase function and the backwards proposal towards guide's wo (guiding.guided_scatter):
    phase (with F) over the mixture density."""
    el, elm1 = side_eta(s.eta, outside)
    if crossed:
        p_phase = phase_transmit(s, el, elm1, ix, iy, iz, area, wx, wy, wz)
        p_energy = p_phase
    else:
        p_phase = phase_reflect(s, False, el, elm1, ix, iy, iz, area, wx, wy, wz)
        p_energy = phase_reflect(s, True, el, elm1, ix, iy, iz, area, wx, wy,
                                 wz) if s.has_f else p_phase
    next_side = outside != crossed
    nz = guide.z if next_side else -guide.z
    e_next = side_eta(s.eta, next_side)[0] if not s.conductor else 1.0
    arz = wz if crossed else -wz  # arriving direction in the next event's frame
    p_adj = adjoint_density(s, -wx, -wy, arz, guide.x, guide.y, nz, guide.area, e_next)
    if not s.conductor:
        p_adj *= 0.5
    mixture = (1.0 - BACKWARDS) * p_phase + BACKWARDS * p_adj
    return p_energy / mixture if mixture > 0.0 else 0.0
