"""Compiled (numba) eval, pdf and sample of RoughDielectric and RoughConductor (GGX, Beckmann).

The numpy code in the model classes is the reference; these kernels evaluate it pair by pair
from the scalar formulas of primitives.py, and a test holds them to it. They are used
automatically when numba imports (the gonio[fast] extra); compiled code is cached on disk. GGX
dielectric eval and visible-normal pdf run in branch-free blocks that LLVM turns into 512-bit
SIMD lanes, with the formulas rearranged to 3 sqrt and 1 division per pair (docs/bsdf.md,
Performance); a pair the block cannot vouch for is handed to the scalar kernel. The others are
scalar per-pair loops, all parallel over pairs (prange); batches below SERIAL_BELOW pairs run
on the calling thread. sample() is compiled for GGX and for Beckmann with Walter's sampler
(Distribution.compiled_samplings)."""

from __future__ import annotations

import math
import os
from enum import IntEnum

import numpy as np

# OpenMP's threads otherwise spin for a while after each parallel call: on the bench, which
# evaluates small batches between protocol waits, that burned a whole core per process
# (0.48 s of CPU in 0.45 s of wall for 200 calls 2 ms apart; 0.04 s passive) and the large
# batches run no slower. Set before numba's threading layer starts; a user's setting wins.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

from model.bsdf.constants import COS_HORIZON, STIRLING_FROM, Masking, Ndf, Sampling
from model.bsdf.primitives import (
    COMPILED,
    conductor_fresnel,
    cos_lambda,
    cos_sin_2pi,
    dielectric_transmittance,
    fresnel_toward,
    g2_over_cosines,
    log_beta,
    normal_density,
    normal_pdf,
    sample_normal,
    transmittance_e,
    unit,
    walter_scale,
)
from model.cluster import run_with_one_kernel_thread
from model.kernel_cache import compiled

#: True when numba imports: the kernels below exist only then.
AVAILABLE = COMPILED
#: Pairs below which a kernel runs on the calling thread alone: waking the parallel kernels'
#: passive OpenMP threads took 1-4 ms per call on a loaded machine when calls come apart (the
#: bench evaluates a few pairs per reading), where 8192 pairs cost about 0.1 ms on one core;
#: larger batches (a fit's aperture rules) still gain from the threads.
SERIAL_BELOW = 1 << 13


class DielectricBlock(IntEnum):
    """What a GGX dielectric SIMD block computes per pair."""

    SEPARABLE_EVAL = 0
    CORRELATED_EVAL = 1
    VISIBLE_PDF = 2


if AVAILABLE:
    from numba import prange
    from numba.core import types
    from numba.extending import intrinsic

    @intrinsic
    def _prefer_512_bit_vectors(typingctx):
        """Mark the calling function for 512-bit SIMD: LLVM's tuning for AVX-512 cores keeps
        loops at 256 bits unless a function asks (about 1.8x for the GGX block loop here).
        llvmlite knows no string attributes, hence the plain set.add."""
        def codegen(context, builder, signature, args):
            set.add(builder.function.attributes, '"prefer-vector-width"="512"')
            return context.get_dummy_value()

        return types.none(), codegen

    @compiled(error_model="numpy")
    def _dielectric_one(wi, wo, k, ndf, ax, ay, eta, masking, refl, trans, sampling, want_pdf):
        ix, iy, iz = unit(wi[k, 0], wi[k, 1], wi[k, 2])
        ox, oy, oz = unit(wo[k, 0], wo[k, 1], wo[k, 2])
        return dielectric_unit(ix, iy, iz, ox, oy, oz, ndf, ax, ay, eta, masking, refl, trans,
                               sampling, want_pdf, math.nan, math.nan)

    @compiled(error_model="numpy")
    def dielectric_unit(ix, iy, iz, ox, oy, oz, ndf, ax, ay, eta, masking, refl, trans,
                        sampling, want_pdf, li, lo):
        """RoughDielectric's eval or pdf at unit wi = (ix, iy, iz), wo = (ox, oy, oz); li, lo:
        |z| Lambda of wi and of wo (cos_lambda) where the caller has them, nan to compute them
        here (only an eval needs them)."""
        e = eta
        em1 = eta - 1.0
        if iz < 0.0:
            iz = -iz
            oz = -oz
            e = 1.0 / eta
            em1 = (1.0 - eta) / eta
        if iz <= COS_HORIZON or abs(oz) <= COS_HORIZON:
            return 0.0
        both = refl and trans
        if oz > 0.0:
            if not refl:
                return 0.0
            hx, hy, hz = unit(ix + ox, iy + oy, iz + oz)
            c = ix * hx + iy * hy + iz * hz
            fr = fresnel_toward(c, e, em1)
            if want_pdf:
                choice = fr if both else 1.0
                om = ox * hx + oy * hy + oz * hz
                return choice * normal_pdf(ndf, ax, ay, sampling, ix, iy, iz, hx, hy, hz) / (
                    4.0 * om)
            li = cos_lambda(ndf, ax, ay, ix, iy, iz) if math.isnan(li) else li
            lo = cos_lambda(ndf, ax, ay, ox, oy, oz) if math.isnan(lo) else lo
            return (0.25 * fr * normal_density(ndf, ax, ay, hx, hy, hz)
                    * g2_over_cosines(masking, iz, oz, li, lo, False))
        if not trans:
            return 0.0
        vx = (ix + ox) + em1 * ox
        vy = (iy + oy) + em1 * oy
        vz = (iz + oz) + em1 * oz
        n2 = vx * vx + vy * vy + vz * vz
        if n2 <= 0.0:
            return 0.0
        inv = -1.0 / math.sqrt(n2)
        mx, my, mz = vx * inv, vy * inv, vz * inv
        if mz < 0.0:
            mx, my, mz = -mx, -my, -mz
        im = ix * mx + iy * my + iz * mz
        om = -(ox * mx + oy * my + oz * mz)
        if not (mz > 0.0 and im > 0.0 and om > 0.0):
            return 0.0
        if want_pdf:
            choice = dielectric_transmittance(im, om, e) if both else 1.0
            return (choice * normal_pdf(ndf, ax, ay, sampling, ix, iy, iz, mx, my, mz)
                    * e * e * om / n2)
        ft = dielectric_transmittance(im, om, e)
        li = cos_lambda(ndf, ax, ay, ix, iy, iz) if math.isnan(li) else li
        lo = cos_lambda(ndf, ax, ay, ox, oy, oz) if math.isnan(lo) else lo
        return (im * om * e * e * ft * normal_density(ndf, ax, ay, mx, my, mz)
                * g2_over_cosines(masking, iz, abs(oz), li, lo, True) / n2)

    @compiled(parallel=True, error_model="numpy")
    def _dielectric(wi, wo, ndf, ax, ay, eta, masking, refl, trans, sampling, want_pdf):
        """Pair-by-pair eval (want_pdf False) or pdf of RoughDielectric, pairs of shape (N, 3)."""
        out = np.empty(wi.shape[0])
        for k in prange(wi.shape[0]):
            out[k] = _dielectric_one(wi, wo, k, ndf, ax, ay, eta, masking, refl, trans,
                                     sampling, want_pdf)
        return out

    @compiled(error_model="numpy")
    def _conductor_one(wi, wo, k, ndf, ax, ay, has_f, n_c, masking, sampling, want_pdf):
        ix, iy, iz = unit(wi[k, 0], wi[k, 1], wi[k, 2])
        ox, oy, oz = unit(wo[k, 0], wo[k, 1], wo[k, 2])
        return conductor_unit(ix, iy, iz, ox, oy, oz, ndf, ax, ay, has_f, n_c, masking,
                              sampling, want_pdf, math.nan, math.nan)

    @compiled(error_model="numpy")
    def conductor_unit(ix, iy, iz, ox, oy, oz, ndf, ax, ay, has_f, n_c, masking, sampling,
                       want_pdf, li, lo):
        """RoughConductor's eval or pdf at unit wi, wo; li, lo as dielectric_unit takes them."""
        if iz <= COS_HORIZON or oz <= COS_HORIZON:
            return 0.0
        hx, hy, hz = unit(ix + ox, iy + oy, iz + oz)
        c = ix * hx + iy * hy + iz * hz
        if want_pdf:
            return normal_pdf(ndf, ax, ay, sampling, ix, iy, iz, hx, hy, hz) / (
                4.0 * (ox * hx + oy * hy + oz * hz))
        f = conductor_fresnel(c, has_f, n_c)
        li = cos_lambda(ndf, ax, ay, ix, iy, iz) if math.isnan(li) else li
        lo = cos_lambda(ndf, ax, ay, ox, oy, oz) if math.isnan(lo) else lo
        return (0.25 * f * normal_density(ndf, ax, ay, hx, hy, hz)
                * g2_over_cosines(masking, iz, oz, li, lo, False))

    @compiled(parallel=True, error_model="numpy")
    def _conductor(wi, wo, ndf, ax, ay, has_f, n_c, masking, sampling, want_pdf):
        """Pair-by-pair eval (want_pdf False) or pdf of RoughConductor, pairs (N, 3)."""
        out = np.empty(wi.shape[0])
        for k in prange(wi.shape[0]):
            out[k] = _conductor_one(wi, wo, k, ndf, ax, ay, has_f, n_c, masking, sampling,
                                    want_pdf)
        return out

    #: Pairs per block of the SIMD kernel: transposed into cache-resident arrays, then one
    #: branch-free loop over the block, then a scalar pass over the pairs it hands back.
    BLOCK = 1024
    #: In a block whose directions all have squared length 1 + d, |d| <= UNIT_TOL, the SIMD
    #: loop normalises by the series 1 - d/2 + 3 d^2/8 (truncation 5/16 |d|^3 < 4e-19) instead
    #: of a sqrt and a division.
    UNIT_TOL = 1e-6
    #: The SIMD loop hands back pairs with a cosine, or |wi + e wo| (unnormalised half
    #: vector), below SAFE_MIN: its undivided products stay far from under/overflow above it.
    SAFE_MIN = 1e-30
    #: ... and pairs whose numerator or denominator of f falls below TINY (precision lost).
    TINY = 1e-290

    @compiled(error_model="numpy")
    def _normalised(f):
        """A normalised copy of the flat (3 m) directions f."""
        g = np.empty(f.shape[0])
        for j in range(0, f.shape[0], 3):
            inv = 1.0 / math.sqrt(f[j] * f[j] + f[j + 1] * f[j + 1] + f[j + 2] * f[j + 2])
            g[j], g[j + 1], g[j + 2] = f[j] * inv, f[j + 1] * inv, f[j + 2] * inv
        return g

    @compiled(error_model="numpy")
    def _one_plus_lambda(ax, ay, w, k):
        """1 + Lambda of GGX for direction k of w (N, 3), as the scalar kernel computes it."""
        x, y, z = unit(w[k, 0], w[k, 1], w[k, 2])
        return 1.0 + cos_lambda(Ndf.GGX.value, ax, ay, x, y, z) / abs(z)

    @compiled(error_model="numpy")
    def _times_beta(x, ax, ay, wi, wo, k):
        """x B(1 + Lambda_i, 1 + Lambda_o) for pair k (log form, _log_beta), or NaN when that
        is not a finite number above TINY: the caller then recomputes the pair in the scalar
        kernel. The SIMD blocks leave this factor of correlated transmission to it."""
        p, q = _one_plus_lambda(ax, ay, wi, k), _one_plus_lambda(ax, ay, wo, k)
        if max(p, q) < STIRLING_FROM:  # _log_beta's first region without the log and exp
            v = x * (math.gamma(min(p, q)) * (math.gamma(max(p, q)) / math.gamma(p + q)))
        else:
            v = x * math.exp(log_beta(p, q))
        return v if TINY < v < math.inf else math.nan

    @compiled(error_model="numpy", inline="always")
    def _block_constants(ax, ay, eta):
        """Per-call constants of the SIMD blocks: 1/alpha_x, 1/alpha_y, pi alpha_x alpha_y, and
        for light arriving from inside 1/eta and 1/eta - 1; eta^2 - 1 from outside and
        (1/eta)^2 - 1 from inside."""
        e_in = 1.0 / eta
        em1_in = (1.0 - eta) / eta
        return (1.0 / ax, 1.0 / ay, math.pi * ax * ay, e_in, em1_in, (eta - 1.0) * (eta + 1.0),
                em1_in * (e_in + 1.0))

    @compiled(error_model="numpy")
    def _ggx_dielectric_block(fi, fo, ax, ay, eta, mode, refl_on, trans_on, res):
        """SIMD loop of _ggx_dielectric over flat (3 m) wi and wo into res (m): 3 sqrt and 1
        division per pair; pairs it cannot vouch for (off unit length, near-grazing, tiny or
        huge intermediates) are left NaN. Correlated transmission (CORRELATED_EVAL) leaves
        -f / B(P, Q) in res, negative as the mark for the caller to multiply the Beta function in
        (_times_beta); the block spends no division and no store on it.
        Calls nothing but inlined helpers: numba compiles a callee with its caller's fastmath
        flags, so that kernels stay free of any flags given here."""
        _prefer_512_bit_vectors()
        inv_ax, inv_ay, pi_axay, e_in, em1_in, e2m1_out, e2m1_in = _block_constants(ax, ay, eta)
        both = refl_on and trans_on
        separable = mode == DielectricBlock.SEPARABLE_EVAL
        correlated = mode == DielectricBlock.CORRELATED_EVAL
        k_refl = 1.0 if separable else 0.5  # 0.25 and the G2 or pdf numerator (see docs)
        k_trans = 4.0 if separable else (1.0 if correlated else 2.0)
        # pdf: Fresnel is the lobe choice, 1 for one lobe
        fresnel = mode != DielectricBlock.VISIBLE_PDF or both
        far = 0
        for j in range(res.shape[0]):
            ix, iy, iz = fi[3 * j], fi[3 * j + 1], fi[3 * j + 2]
            ox, oy, oz = fo[3 * j], fo[3 * j + 1], fo[3 * j + 2]
            di = ix * ix + iy * iy + iz * iz - 1.0
            do = ox * ox + oy * oy + oz * oz - 1.0
            ri = 1.0 + di * (-0.5 + 0.375 * di)
            ro = 1.0 + do * (-0.5 + 0.375 * do)
            inside = iz < 0.0
            ri_z = -ri if inside else ri  # mirror so that wi is on the upper side
            ro_z = -ro if inside else ro
            ix, iy, iz = ix * ri, iy * ri, iz * ri_z
            ox, oy, oz = ox * ro, oy * ro, oz * ro_z
            e = e_in if inside else eta
            em1 = em1_in if inside else eta - 1.0
            e2m1 = e2m1_in if inside else e2m1_out
            e2 = e * e
            refl = oz > 0.0
            aoz = abs(oz)
            # half vector v = wi + e wo (reflection: wi + wo), unnormalised, turned to v.z >= 0
            t = 0.0 if refl else em1
            vx, vy, vz = (ix + ox) + t * ox, (iy + oy) + t * oy, (iz + oz) + t * oz
            n2 = vx * vx + vy * vy + vz * vz
            sv = -1.0 if vz < 0.0 else 1.0
            vi = sv * (ix * vx + iy * vy + iz * vz)
            vo = sv * (ox * vx + oy * vy + oz * vz)
            # Fresnel from c^2, (e cos_t)^2 and p = c e cos_t: reflection c^2 = |v|^2 / 4
            # (|wi| = |wo| = 1); transmission c = wi.v, e cos_t = -e wo.v (homogeneous in v)
            c2 = 0.25 * n2 if refl else vi * vi
            e_ct2 = e2m1 + c2 if refl else e2 * (vo * vo)
            tir = e_ct2 <= 0.0
            e_ct2 = max(e_ct2, 0.0)
            p = math.sqrt(c2 * e_ct2)
            a = c2 + e_ct2 + 2.0 * p  # (c + e cos_t)^2
            b = e2 * e2 * c2 + e_ct2 + (2.0 * e2) * p  # (e^2 c + e cos_t)^2
            x = c2 * (e2 + 1.0) - 1.0
            # D = n2^2 / (pi ax ay q^2); Smith: iz + cos_i Lambda_i = (iz + s_i) / 2 exactly
            q = vz * vz + ((vx * inv_ax) ** 2 + (vy * inv_ay) ** 2)
            s_i = math.sqrt(iz * iz + ((ax * ix) ** 2 + (ay * iy) ** 2))
            s_o = math.sqrt(aoz * aoz + ((ax * ox) ** 2 + (ay * oy) ** 2))
            if separable:
                g_den = (iz + s_i) * (aoz + s_o)
            elif correlated:
                # transmission: G2 / (iz aoz) = B(P, Q) / (iz aoz), B from the caller
                g_den = aoz * s_i + iz * s_o if refl else iz * aoz
            else:
                g_den = iz + s_i
            # F = e2m1^2 (b^2 + x^2 a^2) / (2 a^2 b^2); T = 2 p (b + e^2 a) / (a b)
            if refl:
                fresnel_here = fresnel and not tir
                num = (k_refl * n2 * n2) * (0.5 * e2m1 * e2m1 * (b * b + x * x * (a * a))
                                            if fresnel_here else 1.0)
                den = (a * b) * (a * b) if fresnel_here else 1.0
            else:
                num = (k_trans * e2) * vi * -vo * (2.0 * p * (b + e2 * a) if fresnel else 1.0)
                den = a * b if fresnel else 1.0
            den = den * (pi_axay * (q * q) * g_den)
            val = num / den
            live = refl_on if refl else (trans_on & (vi > 0.0) & (vo < 0.0))
            ok = (iz > COS_HORIZON) & (aoz > COS_HORIZON) & (n2 > 0.0) & (vz * sv > 0.0) & live
            far += (abs(di) > UNIT_TOL) | (abs(do) > UNIT_TOL)
            safe = ((abs(di) <= UNIT_TOL) & (abs(do) <= UNIT_TOL) & (iz >= SAFE_MIN)
                    & (aoz >= SAFE_MIN) & (n2 >= SAFE_MIN * SAFE_MIN))
            sure = (num > TINY) & (den > TINY) & (val < math.inf)
            val = -val if correlated & (not refl) else val
            res[j] = math.nan if not safe or (ok and not sure) else (val if ok else 0.0)
        return far

    @compiled(parallel=True, error_model="numpy")
    def _ggx_dielectric(wi, wo, ax, ay, eta, mode, refl_on, trans_on):
        """GGX dielectric eval or visible pdf (mode, a DielectricBlock): SIMD blocks, the Beta
        factor of correlated transmission, then the pairs left NaN by the scalar kernel."""
        n = wi.shape[0]
        out = np.empty(n)
        correlated = mode == DielectricBlock.CORRELATED_EVAL
        masking = Masking.CORRELATED.value if correlated else Masking.SEPARABLE.value
        want_pdf = mode == DielectricBlock.VISIBLE_PDF
        for b in prange((n + BLOCK - 1) // BLOCK):
            start, stop = b * BLOCK, min(n, (b + 1) * BLOCK)
            # ravel: views of C-contiguous pairs, block copies of broadcast ones
            fi, fo = wi[start:stop].ravel(), wo[start:stop].ravel()
            if _ggx_dielectric_block(fi, fo, ax, ay, eta, mode, refl_on, trans_on,
                                     out[start:stop]):  # directions off unit length: again
                _ggx_dielectric_block(_normalised(fi), _normalised(fo), ax, ay, eta, mode,
                                      refl_on, trans_on, out[start:stop])
            for k in range(start, stop):
                if out[k] < 0.0:  # correlated transmission: times B(1 + Lambda_i, 1 + Lambda_o)
                    out[k] = _times_beta(-out[k], ax, ay, wi, wo, k)
                if math.isnan(out[k]):
                    out[k] = _dielectric_one(wi, wo, k, Ndf.GGX.value, ax, ay, eta, masking,
                                             refl_on, trans_on, Sampling.VISIBLE.value,
                                             want_pdf)
        return out

    def launch(kernel, n: int, *args):
        """kernel(*args) over n pairs: on the calling thread alone below SERIAL_BELOW pairs
        (numba's thread count is per calling thread, so other threads keep theirs)."""
        return kernel(*args) if n >= SERIAL_BELOW else run_with_one_kernel_thread(kernel, *args)

    def dielectric(wi: np.ndarray, wo: np.ndarray, ndf: Ndf, ax: float, ay: float, eta: float,
                   masking: Masking, refl: bool, trans: bool, sampling: Sampling,
                   want_pdf: bool) -> np.ndarray:
        """eval (want_pdf False) or pdf of RoughDielectric for pairs wi, wo of shape (N, 3).

        GGX eval and visible-normal pdf run in the branch-free SIMD blocks (both lobes share one
        half vector, D and G2 and differ in Fresnel factor and Jacobian, so each pair computes
        one set and selects; algebraically the numpy path's formulas), the rest pair by pair.
        """
        if ndf == Ndf.GGX and not want_pdf:
            mode = (DielectricBlock.CORRELATED_EVAL if masking == Masking.CORRELATED
                    else DielectricBlock.SEPARABLE_EVAL)
            return launch(_ggx_dielectric, len(wi), wi, wo, ax, ay, eta, int(mode), refl,
                           trans)
        if ndf == Ndf.GGX and sampling == Sampling.VISIBLE:
            return launch(_ggx_dielectric, len(wi), wi, wo, ax, ay, eta,
                           int(DielectricBlock.VISIBLE_PDF), refl, trans)
        return launch(_dielectric, len(wi), wi, wo, int(ndf), ax, ay, eta, int(masking), refl,
                       trans, int(sampling), want_pdf)

    def conductor(wi: np.ndarray, wo: np.ndarray, ndf: Ndf, ax: float, ay: float, has_f: bool,
                  n_c: complex, masking: Masking, sampling: Sampling,
                  want_pdf: bool) -> np.ndarray:
        """eval (want_pdf False) or pdf of RoughConductor for pairs of shape (N, 3); has_f
        False: F = 1 (n_c unused)."""
        return launch(_conductor, len(wi), wi, wo, int(ndf), ax, ay, has_f, n_c, int(masking),
                       int(sampling), want_pdf)

    @compiled(error_model="numpy")
    def _sampling_weight(ndf, ax, ay, masking, sampling, ix, iy, iz, li, ox, oy, oz, mx, my, mz,
                         c, transmitted):
        """f |cos o| / pdf without Fresnel and lobe choice (MicrofacetModel._sampling_weight)."""
        aoz = abs(oz)
        lo = cos_lambda(ndf, ax, ay, ox, oy, oz)
        g2oc = g2_over_cosines(masking, iz, aoz, li, lo, transmitted)
        if sampling == Sampling.VISIBLE:
            return aoz * (iz + li) * g2oc
        ks = walter_scale(iz)
        d_s = normal_density(ndf, ax * ks, ay * ks, mx, my, mz)
        if not (d_s > 0.0 and mz > 0.0):
            return 0.0
        return normal_density(ndf, ax, ay, mx, my, mz) / d_s * c * aoz * g2oc / mz

    @compiled(parallel=True, error_model="numpy")
    def _conductor_sample(wi, u, ndf, ax, ay, has_f, n_c, masking, sampling):
        """sample() of RoughConductor pair by pair: (wo, weight, pdf), failed samples 0."""
        n = wi.shape[0]
        wo = np.zeros((n, 3))
        weight = np.zeros(n)
        pdf = np.zeros(n)
        for k in prange(n):
            ix, iy, iz = unit(wi[k, 0], wi[k, 1], wi[k, 2])
            if not iz > COS_HORIZON:
                continue
            mx, my, mz = sample_normal(ndf, ax, ay, sampling, ix, iy, iz, u[k, 0], u[k, 1])
            c = ix * mx + iy * my + iz * mz
            ox, oy, oz = 2.0 * c * mx - ix, 2.0 * c * my - iy, 2.0 * c * mz - iz
            if not (c > 0.0 and oz > COS_HORIZON):
                continue
            p = normal_pdf(ndf, ax, ay, sampling, ix, iy, iz, mx, my, mz) / (4.0 * c)
            if not p > 0.0:
                continue
            li = cos_lambda(ndf, ax, ay, ix, iy, iz)
            w = _sampling_weight(ndf, ax, ay, masking, sampling, ix, iy, iz, li, ox, oy, oz,
                                 mx, my, mz, c, False)
            wo[k, 0], wo[k, 1], wo[k, 2] = ox, oy, oz
            weight[k] = conductor_fresnel(c, has_f, n_c) * w
            pdf[k] = p
        return wo, weight, pdf

    @compiled(error_model="numpy")
    def _dielectric_sample_one(wi, u, k, ndf, ax, ay, eta, masking, refl_on, trans_on,
                               sampling):
        """One sample of RoughDielectric for pair k: (ox, oy, oz, weight, pdf), all 0 if it
        failed (the numpy path's formulas, pair by pair)."""
        both = refl_on and trans_on
        ix, iy, iz = unit(wi[k, 0], wi[k, 1], wi[k, 2])
        sgn = -1.0 if iz < 0.0 else 1.0
        iz = iz * sgn
        e = 1.0 / eta if sgn < 0.0 else eta
        em1 = (1.0 - eta) / eta if sgn < 0.0 else eta - 1.0
        mx, my, mz = sample_normal(ndf, ax, ay, sampling, ix, iy, iz, u[k, 0], u[k, 1])
        c = ix * mx + iy * my + iz * mz
        fr = fresnel_toward(abs(c), e, em1)
        e_ct = math.sqrt(max(em1 * (e + 1.0) + c * c, 0.0))
        ft = transmittance_e(abs(c), e_ct, e) if e_ct > 0.0 else 0.0
        reflected = u[k, 2] < fr if both else refl_on
        if reflected:
            ox, oy, oz = 2.0 * c * mx - ix, 2.0 * c * my - iy, 2.0 * c * mz - iz
        else:
            gap = -em1 * (e + 1.0) / (c + e_ct if c + e_ct > 0.0 else 1.0)
            ox, oy, oz = (-ix + gap * mx) / e, (-iy + gap * my) / e, (-iz + gap * mz) / e
        ok = c > 0.0 and mz > 0.0 and iz > COS_HORIZON and abs(oz) > COS_HORIZON
        ok = ok and ((oz > 0.0) if reflected else (oz < 0.0 and ft > 0.0))
        if not ok:
            return 0.0, 0.0, 0.0, 0.0, 0.0
        lobe = fr if reflected else ft
        if reflected:
            jac = 1.0 / (4.0 * abs(c))
        else:
            jac = e * e_ct / (gap * gap) if gap != 0.0 else math.inf
        p = (lobe if both else 1.0) * normal_pdf(ndf, ax, ay, sampling, ix, iy, iz, mx,
                                                    my, mz) * jac
        li = cos_lambda(ndf, ax, ay, ix, iy, iz)
        w = _sampling_weight(ndf, ax, ay, masking, sampling, ix, iy, iz, li, ox, oy, oz,
                             mx, my, mz, c, not reflected)
        if not p > 0.0:
            return 0.0, 0.0, 0.0, 0.0, 0.0
        return ox, oy, oz * sgn, (1.0 if both else lobe) * w, p

    @compiled(parallel=True, error_model="numpy")
    def _dielectric_sample(wi, u, ndf, ax, ay, eta, masking, refl_on, trans_on, sampling):
        """sample() of RoughDielectric pair by pair: (wo, weight, pdf), failed samples 0."""
        n = wi.shape[0]
        wo = np.empty((n, 3))
        weight = np.empty(n)
        pdf = np.empty(n)
        for k in prange(n):
            wo[k, 0], wo[k, 1], wo[k, 2], weight[k], pdf[k] = _dielectric_sample_one(
                wi, u, k, ndf, ax, ay, eta, masking, refl_on, trans_on, sampling)
        return wo, weight, pdf

    @compiled(error_model="numpy")
    def _ggx_visible_sample_block(fi, fu, ax, ay, eta, correlated, refl_on, trans_on, fwo,
                                  weight, pdf):
        """SIMD loop of _ggx_visible_sample over flat (3 m) wi and u into fwo (3 m), weight and
        pdf (m): 9 sqrt and 5 divisions per sample, no libm calls;
        samples it cannot vouch for (wi off unit length or near grazing, u outside [0, 1],
        eta = 1 transmission, tiny or huge results) get pdf NaN. Correlated transmission
        leaves -weight / B(P, Q) in weight, negative as the mark for the caller to multiply
        the Beta function in (_times_beta). Calls nothing but inlined helpers (see
        _ggx_dielectric_block)."""
        _prefer_512_bit_vectors()
        inv_ax, inv_ay, pi_axay, e_in, em1_in, e2m1_out, e2m1_in = _block_constants(ax, ay, eta)
        both = refl_on and trans_on
        far = 0
        for j in range(pdf.shape[0]):
            ix, iy, iz = fi[3 * j], fi[3 * j + 1], fi[3 * j + 2]
            u1, u2, u3 = fu[3 * j], fu[3 * j + 1], fu[3 * j + 2]
            di = ix * ix + iy * iy + iz * iz - 1.0
            ri = 1.0 + di * (-0.5 + 0.375 * di)
            inside = iz < 0.0
            sgn = -1.0 if inside else 1.0
            ix, iy, iz = ix * ri, iy * ri, iz * (ri * sgn)
            e = e_in if inside else eta
            inv_e = eta if inside else e_in
            e2m1 = e2m1_in if inside else e2m1_out
            e2 = e * e
            # visible normal (Heitz 2018) in the stretched frame: hemisphere v, basis t1, t2
            vx, vy, vz = ax * ix, ay * iy, iz
            lat2 = vx * vx + vy * vy
            s_n = math.sqrt(lat2 + vz * vz)
            s_l = math.sqrt(lat2) if lat2 > 0.0 else 1.0
            r = 1.0 / (s_n * s_l)
            inv_n = s_l * r
            t1x = -vy * (s_n * r) if lat2 > 0.0 else 1.0  # (-vy, vx) / |v_xy|
            t1y = vx * (s_n * r) if lat2 > 0.0 else 0.0
            vx, vy, vz = vx * inv_n, vy * inv_n, vz * inv_n
            t2x, t2y, t2z = -vz * t1y, vz * t1x, vx * t1y - vy * t1x
            rad = math.sqrt(u1)
            cos_p, sin_p = cos_sin_2pi(u2)
            p1, p2 = rad * cos_p, rad * sin_p
            h = 0.5 * (1.0 + vz)
            p2 = (1.0 - h) * math.sqrt(max(1.0 - p1 * p1, 0.0)) + h * p2
            p3 = math.sqrt(max(1.0 - p1 * p1 - p2 * p2, 0.0))
            nx = ax * (p1 * t1x + p2 * t2x + p3 * vx)
            ny = ay * (p1 * t1y + p2 * t2y + p3 * vy)
            nz = max(p2 * t2z + p3 * vz, 0.0)
            n2 = nx * nx + ny * ny + nz * nz
            inv_m = 1.0 / math.sqrt(n2)
            mx, my, mz = nx * inv_m, ny * inv_m, nz * inv_m
            c = ix * mx + iy * my + iz * mz
            # Fresnel toward m, one division: 1 / den_s and 1 / den_p from 1 / (den_s den_p)
            e_ct2 = e2m1 + c * c
            e_ct = math.sqrt(max(e_ct2, 0.0))
            den_s = c + e_ct
            den_p = e2 * c + e_ct
            inv = 1.0 / (den_s * den_p)
            r_s, r_p = den_p * inv, den_s * inv
            rs = -e2m1 * r_s * r_s
            rp = e2m1 * (c * c * (e2 + 1.0) - 1.0) * r_p * r_p
            fr = 1.0 if e_ct2 <= 0.0 else 0.5 * (rs * rs + rp * rp)
            ft = 2.0 * (c * e_ct) * (r_s * r_s + e2 * r_p * r_p) if e_ct > 0.0 else 0.0
            reflected = u3 < fr if both else refl_on
            gap = -e2m1 * r_s  # c - e cos_t = (1 - e^2) / (c + e cos_t)
            ox = 2.0 * c * mx - ix if reflected else (gap * mx - ix) * inv_e
            oy = 2.0 * c * my - iy if reflected else (gap * my - iy) * inv_e
            oz = 2.0 * c * mz - iz if reflected else (gap * mz - iz) * inv_e
            aoz = abs(oz)
            # pdf = lobe D(m) c / (iz + Li) * Jacobian, weight = G2 / G1(wi) (times the lobe
            # for one lobe); D = 1 / (pi ax ay q^2), iz + Li = (iz + s_i) / 2
            q = mz * mz + ((mx * inv_ax) ** 2 + (my * inv_ay) ** 2)
            s_i = math.sqrt(iz * iz + ((ax * ix) ** 2 + (ay * iy) ** 2))
            s_o = math.sqrt(aoz * aoz + ((ax * ox) ** 2 + (ay * oy) ** 2))
            lobe = fr if reflected else ft
            choice = lobe if both else 1.0
            w_lobe = 1.0 if both else lobe
            p_num = choice if reflected else choice * (2.0 * c) * e * e_ct
            p_den = pi_axay * (q * q) * (iz + s_i) * (2.0 if reflected else gap * gap)
            # correlated transmission: weight = aoz (iz + Li) B(P, Q) / (iz aoz) = P B(P, Q),
            # P = 1 + Lambda_i = (iz + s_i) / (2 iz): left as (iz + s_i) / (2 iz) without B
            trans_beta = correlated & (not reflected)
            if correlated:
                w_num = iz + s_i if trans_beta else aoz * (iz + s_i)
                w_den = 2.0 * iz if trans_beta else aoz * s_i + iz * s_o
            else:
                w_num, w_den = 2.0 * aoz, aoz + s_o
            # one division for pdf and weight: p = p_num w_den / (p_den w_den) and so on
            inv = 1.0 / (p_den * w_den)
            p = p_num * w_den * inv
            w = w_lobe * w_num * p_den * inv
            ok = ((c > 0.0) & (mz > 0.0) & (iz > COS_HORIZON) & (aoz > COS_HORIZON)
                  & ((oz > 0.0) if reflected else ((oz < 0.0) & (ft > 0.0))))
            far += abs(di) > UNIT_TOL
            safe = ((abs(di) <= UNIT_TOL) & (iz >= SAFE_MIN) & (u1 >= 0.0) & (u1 <= 1.0)
                    & (u2 >= 0.0) & (u2 <= 1.0))
            sure = ((p > TINY) & (p < math.inf) & (w > TINY) & (w < math.inf)
                    & (p_den * w_den > TINY))
            fwo[3 * j] = ox if ok else 0.0
            fwo[3 * j + 1] = oy if ok else 0.0
            fwo[3 * j + 2] = oz * sgn if ok else 0.0
            weight[j] = (-w if trans_beta else w) if ok else 0.0
            pdf[j] = math.nan if not safe or (ok and not sure) else (p if ok else 0.0)
        return far

    @compiled(parallel=True, error_model="numpy")
    def _ggx_visible_sample(wi, u, ax, ay, eta, correlated, refl_on, trans_on):
        """sample() of the GGX RoughDielectric with visible-normal sampling: SIMD blocks, the
        Beta factor of correlated transmission, then the samples left NaN by
        _dielectric_sample_one."""
        n = wi.shape[0]
        wo = np.empty(3 * n)
        wo2 = wo.reshape((n, 3))
        weight = np.empty(n)
        pdf = np.empty(n)
        masking = Masking.CORRELATED.value if correlated else Masking.SEPARABLE.value
        for b in prange((n + BLOCK - 1) // BLOCK):
            start, stop = b * BLOCK, min(n, (b + 1) * BLOCK)
            fi, fu = wi[start:stop].ravel(), u[start:stop].ravel()
            outs = wo[3 * start:3 * stop], weight[start:stop], pdf[start:stop]
            if _ggx_visible_sample_block(fi, fu, ax, ay, eta, correlated, refl_on, trans_on,
                                         *outs):  # directions off unit length: again
                _ggx_visible_sample_block(_normalised(fi), fu, ax, ay, eta, correlated,
                                          refl_on, trans_on, *outs)
            for k in range(start, stop):
                if weight[k] < 0.0 and not math.isnan(pdf[k]):  # correlated transmission
                    weight[k] = _times_beta(-weight[k], ax, ay, wi, wo2, k)
                    pdf[k] = math.nan if math.isnan(weight[k]) else pdf[k]
                if math.isnan(pdf[k]):
                    wo[3 * k], wo[3 * k + 1], wo[3 * k + 2], weight[k], pdf[k] = (
                        _dielectric_sample_one(wi, u, k, Ndf.GGX.value, ax, ay, eta, masking,
                                               refl_on, trans_on, Sampling.VISIBLE.value))
        return wo2, weight, pdf

    def dielectric_sample(wi: np.ndarray, u: np.ndarray, ndf: Ndf, ax: float, ay: float,
                          eta: float, masking: Masking, refl_on: bool, trans_on: bool,
                          sampling: Sampling) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """sample() of RoughDielectric: (wo, weight, pdf), failed samples all zero; GGX with
        visible normals in SIMD blocks, the rest pair by pair."""
        if ndf == Ndf.GGX and sampling == Sampling.VISIBLE:
            return launch(_ggx_visible_sample, len(wi), wi, u, ax, ay, eta,
                           masking == Masking.CORRELATED, refl_on, trans_on)
        return launch(_dielectric_sample, len(wi), wi, u, int(ndf), ax, ay, eta, int(masking),
                       refl_on, trans_on, int(sampling))

    def conductor_sample(wi: np.ndarray, u: np.ndarray, ndf: Ndf, ax: float, ay: float,
                         has_f: bool, n_c: complex, masking: Masking,
                         sampling: Sampling) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """sample() of RoughConductor: (wo, weight, pdf), failed samples all zero."""
        return launch(_conductor_sample, len(wi), wi, u, int(ndf), ax, ay, has_f, n_c,
                       int(masking), int(sampling))
