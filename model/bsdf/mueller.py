"""Mueller matrices of one microfacet event seen in the macro-surface's Stokes frames.

A facet with normal m turns the Jones vector diag(a_s, a_p) in its own s/p frame; the Stokes
vectors of wi and wo are given in the macro surface's frames (docs/bsdf.md, Polarisation), so
the facet's Mueller matrix is rotated in from wi's frame and out to wo's frame. Everything is
normalised to M00 = 1: the models multiply by their unpolarised value."""

from __future__ import annotations

import numpy as np

from model.bsdf.vectors import dot

#: s of a beam along +-z, where the plane of incidence is not defined: the x-z plane's
#: (the limit of an incidence plane at azimuth 0 for the incident beam).
S_AT_NORMAL = np.array([0.0, -1.0, 0.0])


def stokes_frame(k: np.ndarray, axis: np.ndarray | None = None,
                 fallback: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(s, p) of beams propagating along unit k (..., 3): s = unit(axis x k), p = k x s.

    axis is the normal that defines the plane of incidence (+z when None); where axis x k
    vanishes s is `fallback` made perpendicular to k (S_AT_NORMAL when None).
    (s, p, k) is right-handed, so S3 > 0 is a field turning from s toward p."""
    axis = np.array([0.0, 0.0, 1.0]) if axis is None else axis
    s = np.cross(axis, k)
    norm = np.sqrt(dot(s, s))
    bare = norm <= 1e-300
    if bare.any():
        base = np.broadcast_to(S_AT_NORMAL if fallback is None else fallback, s.shape)
        base = base - dot(base, k)[..., None] * k
        s = np.where(bare[..., None], base, s)
        norm = np.sqrt(dot(s, s))
    s = s / np.where(norm > 0, norm, 1.0)[..., None]
    return s, np.cross(k, s)


def rotator(s_from: np.ndarray, p_from: np.ndarray, s_to: np.ndarray) -> np.ndarray:
    """Mueller matrix (..., 4, 4) that re-expresses a Stokes vector given in the frame
    (s_from, p_from) in the frame of the same beam whose s is s_to.

    With s_to = cos(phi) s_from + sin(phi) p_from: S1' = cos 2phi S1 + sin 2phi S2,
    S2' = -sin 2phi S1 + cos 2phi S2; S0 and S3 unchanged. (cos, sin) are renormalised, so a
    frame known only to rounding still gives an exact rotation."""
    cos, sin = dot(s_to, s_from), dot(s_to, p_from)
    r = np.hypot(cos, sin)
    ok = r > 0
    cos = np.where(ok, cos / np.where(ok, r, 1.0), 1.0)
    sin = np.where(ok, sin / np.where(ok, r, 1.0), 0.0)
    c2, s2 = cos * cos - sin * sin, 2.0 * cos * sin
    out = np.zeros(cos.shape + (4, 4))
    out[..., 0, 0] = out[..., 3, 3] = 1.0
    out[..., 1, 1] = out[..., 2, 2] = c2
    out[..., 1, 2] = s2
    out[..., 2, 1] = -s2
    return out


def jones_diagonal_mueller(a_s: np.ndarray, a_p: np.ndarray) -> np.ndarray:
    """Mueller matrix (..., 4, 4) of the Jones matrix diag(a_s, a_p), divided by its M00.

    With A = |a_s|^2, B = |a_p|^2, x + iy = conj(a_s) a_p: M00 = M11 = (A + B)/2,
    M01 = M10 = (A - B)/2, M22 = M33 = x, M23 = -y, M32 = y. The amplitudes are scaled by the
    larger one first (no underflow); both zero gives the identity."""
    a_s = np.asarray(a_s, dtype=np.complex128)
    a_p = np.asarray(a_p, dtype=np.complex128)
    scale = np.maximum(np.abs(a_s), np.abs(a_p))
    live = scale > 0
    scale = np.where(live, scale, 1.0)
    a_s, a_p = a_s / scale, a_p / scale
    big_a, big_b = np.abs(a_s) ** 2, np.abs(a_p) ** 2
    total = np.where(live, big_a + big_b, 2.0)
    cross = 2.0 * np.conj(a_s) * a_p / total
    out = np.zeros(scale.shape + (4, 4))
    out[..., 0, 0] = out[..., 1, 1] = 1.0
    out[..., 0, 1] = out[..., 1, 0] = np.where(live, (big_a - big_b) / total, 0.0)
    out[..., 2, 2] = out[..., 3, 3] = np.where(live, cross.real, 1.0)
    out[..., 2, 3] = np.where(live, -cross.imag, 0.0)
    out[..., 3, 2] = np.where(live, cross.imag, 0.0)
    return out


def facet_mueller(wi: np.ndarray, wo: np.ndarray, m: np.ndarray, a_s: np.ndarray,
                  a_p: np.ndarray) -> np.ndarray:
    """Normalised Mueller matrix (..., 4, 4) of light from unit wi leaving along unit wo by one
    facet of normal m (either sign) with Jones amplitudes a_s, a_p in the facet's s/p frames,
    in the macro Stokes frames of wi (beam along -wi) and wo (beam along wo).

    The facet's s, unit(m x k_in), is shared by the incident, reflected and refracted beams;
    at normal incidence on the facet any s gives the same product, so wi's is taken."""
    k_in = -wi
    s_in, p_in = stokes_frame(k_in)
    s_out, p_out = stokes_frame(wo)
    s_facet, p_facet_in = stokes_frame(k_in, m, s_in)
    p_facet_out = np.cross(wo, s_facet)
    into = rotator(s_in, p_in, s_facet)
    out_of = rotator(s_facet, p_facet_out, s_out)
    return out_of @ jones_diagonal_mueller(a_s, a_p) @ into
