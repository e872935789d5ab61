"""Compiled (numba) eval_mueller of RoughDielectric and RoughConductor, pair by pair.

The numpy path (mueller.py and the models' _mueller_shape) is the reference; this evaluates the
same facet, Fresnel amplitudes and frame rotations per pair, without the (n, 4, 4) temporaries,
and multiplies by the unpolarised eval it is given. tests/bsdf_mueller holds it to the numpy
path. Only imported when numba is (model.bsdf.kernels.AVAILABLE)."""

from __future__ import annotations

import math

import numpy as np
from numba import prange

from model.bsdf.constants import COS_HORIZON
from model.bsdf.kernels import launch
from model.bsdf.primitives import fresnel_amplitudes, inlined, unit
from model.kernel_cache import compiled

#: mueller.S_AT_NORMAL's y (x and z are 0).
NORMAL_SY = -1.0


@inlined
def _cross(ax, ay, az, bx, by, bz):
    return ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx


@inlined
def _frame_s(nx, ny, nz, kx, ky, kz, fx, fy, fz):
    """s = unit(n x k), or the fallback f made perpendicular to k where n x k vanishes
    (mueller.stokes_frame)."""
    sx, sy, sz = _cross(nx, ny, nz, kx, ky, kz)
    norm = math.sqrt(sx * sx + sy * sy + sz * sz)
    if not norm > 1e-300:
        along = fx * kx + fy * ky + fz * kz
        sx, sy, sz = fx - along * kx, fy - along * ky, fz - along * kz
    return unit(sx, sy, sz)


@inlined
def _double_angle(cos, sin):
    """(cos 2phi, sin 2phi) from a (cos, sin) pair known to rounding (mueller.rotator)."""
    r = math.sqrt(cos * cos + sin * sin)  # both within [-1, 1]: no overflow
    if not r > 0.0:
        return 1.0, 0.0
    cos, sin = cos / r, sin / r
    return cos * cos - sin * sin, 2.0 * cos * sin


@inlined
def _facet(out, f, ix, iy, iz, ox, oy, oz, mx, my, mz, a_s, a_p):
    """out (4, 4) = f times mueller.facet_mueller for unit wi, wo, facet normal m and the
    amplitudes a_s, a_p, written out: rotate in, Jones diag(a_s, a_p), rotate out."""
    sx, sy, sz = _frame_s(0.0, 0.0, 1.0, -ix, -iy, -iz, 0.0, NORMAL_SY, 0.0)
    px, py, pz = _cross(-ix, -iy, -iz, sx, sy, sz)
    tx, ty, tz = _frame_s(0.0, 0.0, 1.0, ox, oy, oz, 0.0, NORMAL_SY, 0.0)
    qx, qy, qz = _cross(ox, oy, oz, tx, ty, tz)
    fx, fy, fz = _frame_s(mx, my, mz, -ix, -iy, -iz, sx, sy, sz)
    gx, gy, gz = _cross(ox, oy, oz, fx, fy, fz)
    ci, si = _double_angle(fx * sx + fy * sy + fz * sz, fx * px + fy * py + fz * pz)
    co, so = _double_angle(tx * fx + ty * fy + tz * fz, tx * gx + ty * gy + tz * gz)
    # any scale within a factor 2 of the largest amplitude keeps the squares from under- or
    # overflowing; the largest component is one without a square root
    scale = max(abs(a_s.real), abs(a_s.imag), abs(a_p.real), abs(a_p.imag))
    d01, x2, y2 = 0.0, 1.0, 0.0
    if scale > 0.0:
        a_s, a_p = a_s / scale, a_p / scale
        big_a = a_s.real * a_s.real + a_s.imag * a_s.imag
        big_b = a_p.real * a_p.real + a_p.imag * a_p.imag
        total = big_a + big_b
        cross = 2.0 * a_s.conjugate() * a_p / total
        d01, x2, y2 = (big_a - big_b) / total, cross.real, cross.imag
    # G = F R_in by rows, then R_out G (mueller.rotator's matrices)
    g1 = (d01, ci, si, 0.0)
    g2 = (0.0, -x2 * si, x2 * ci, -y2)
    out[0, 0], out[0, 1], out[0, 2], out[0, 3] = f, f * d01 * ci, f * d01 * si, 0.0
    for j in range(4):
        out[1, j] = f * (co * g1[j] + so * g2[j])
        out[2, j] = f * (-so * g1[j] + co * g2[j])
    out[3, 0], out[3, 1], out[3, 2], out[3, 3] = 0.0, -f * y2 * si, f * y2 * ci, f * x2


@inlined
def _unit_pair(wi, wo, k):
    ix, iy, iz = unit(wi[k, 0], wi[k, 1], wi[k, 2])
    ox, oy, oz = unit(wo[k, 0], wo[k, 1], wo[k, 2])
    return ix, iy, iz, ox, oy, oz


@inlined
def _identity(out, f):
    for a in range(4):
        for b in range(4):
            out[a, b] = f if a == b else 0.0


@inlined
def _reflection(out, f, ix, iy, iz, ox, oy, oz, n, n2m1):
    """The facet at the reflection half vector with the amplitudes toward index n."""
    mx, my, mz = unit(ix + ox, iy + oy, iz + oz)
    r_s, r_p = fresnel_amplitudes(abs(ix * mx + iy * my + iz * mz), n, n2m1)
    _facet(out, f, ix, iy, iz, ox, oy, oz, mx, my, mz, r_s, r_p)


@compiled(parallel=True, error_model="numpy")
def _dielectric_muellers(wi, wo, f, eta, refl, trans):
    """RoughDielectric._mueller_shape times f, pair by pair (wi from either side)."""
    out = np.empty((wi.shape[0], 4, 4))  # every entry is written
    for k in prange(wi.shape[0]):
        ix, iy, iz, ox, oy, oz = _unit_pair(wi, wo, k)
        sign = -1.0 if iz < 0.0 else 1.0
        e = 1.0 / eta if sign < 0.0 else eta
        em1 = (1.0 - eta) / eta if sign < 0.0 else eta - 1.0
        uz, vz = iz * sign, oz * sign  # wi, wo mirrored so that wi is above
        live = uz > COS_HORIZON and abs(vz) > COS_HORIZON
        if live and vz > 0.0 and refl:
            _reflection(out[k], f[k], ix, iy, iz, ox, oy, oz, complex(e, 0.0),
                        complex(em1 * (e + 1.0), 0.0))
        elif live and vz < 0.0 and trans:
            vx, vy, vv = ix + ox + em1 * ox, iy + oy + em1 * oy, uz + vz + em1 * vz
            mx, my, mz = unit(-vx, -vy, -vv)
            if mz < 0.0:
                mx, my, mz = -mx, -my, -mz
            c = ix * mx + iy * my + uz * mz
            e_ct = -e * (ox * mx + oy * my + vz * mz)
            if mz > 0.0 and c > 0.0 and e_ct > 0.0:
                _facet(out[k], f[k], ix, iy, iz, ox, oy, oz, mx, my, mz * sign,
                       complex(1.0 / (c + e_ct), 0.0), complex(e / (e * e * c + e_ct), 0.0))
            else:
                _identity(out[k], f[k])
        else:
            _identity(out[k], f[k])
    return out


@compiled(parallel=True, error_model="numpy")
def _conductor_muellers(wi, wo, f, has_f, n_c):
    """RoughConductor._mueller_shape times f, pair by pair."""
    out = np.empty((wi.shape[0], 4, 4))  # every entry is written
    n2m1 = (n_c - 1.0) * (n_c + 1.0)
    for k in prange(wi.shape[0]):
        ix, iy, iz, ox, oy, oz = _unit_pair(wi, wo, k)
        if not (iz > COS_HORIZON and oz > COS_HORIZON):
            _identity(out[k], f[k])
        elif has_f:
            _reflection(out[k], f[k], ix, iy, iz, ox, oy, oz, n_c, n2m1)
        else:
            mx, my, mz = unit(ix + ox, iy + oy, iz + oz)
            _facet(out[k], f[k], ix, iy, iz, ox, oy, oz, mx, my, mz, complex(-1.0, 0.0),
                   complex(1.0, 0.0))
    return out


def dielectric_muellers(wi: np.ndarray, wo: np.ndarray, f: np.ndarray, eta: float,
                        refl: bool, trans: bool) -> np.ndarray:
    """(N, 4, 4) Mueller BSDF of RoughDielectric for pairs (N, 3), given its eval f (N,)."""
    return launch(_dielectric_muellers, len(wi), wi, wo, f, eta, refl, trans)


def conductor_muellers(wi: np.ndarray, wo: np.ndarray, f: np.ndarray, has_f: bool,
                       n_c: complex) -> np.ndarray:
    """(N, 4, 4) Mueller BSDF of RoughConductor for pairs (N, 3), given its eval f (N,);
    has_f False: a perfect conductor (n_c unused)."""
    return launch(_conductor_muellers, len(wi), wi, wo, f, has_f, n_c)
