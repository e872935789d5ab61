"""Independent high-precision reference of the BSDF (mpmath, 50 digits), written straight from
Walter et al. 2007 in their own variables (tan theta, erf, Walter's Fresnel eq. 22, Phong Lambda by
numerical quadrature) rather than from the rearranged forms of model.bsdf."""

from __future__ import annotations

import mpmath as mp

mp.mp.dps = 50


def _vec(v):
    v = [mp.mpf(float(x)) for x in v]
    n = mp.sqrt(sum(x * x for x in v))
    return [x / n for x in v]


def _dot(a, b):
    return sum(x * y for x, y in zip(a, b, strict=True))


def _alpha_w2(w, ax, ay):
    """alpha^2 along the azimuth of w: cos^2 phi ax^2 + sin^2 phi ay^2 (ax^2 at the pole)."""
    r2 = w[0] ** 2 + w[1] ** 2
    if r2 == 0:
        return ax * ax
    return (w[0] ** 2 * ax * ax + w[1] ** 2 * ay * ay) / r2


def _tan2(w):
    return (w[0] ** 2 + w[1] ** 2) / w[2] ** 2


def D(name, alpha, m):
    """Textbook D(m) in tan theta and phi."""
    ax, ay = (mp.mpf(a) for a in alpha)
    if m[2] <= 0:
        return mp.mpf(0)
    cos2 = m[2] ** 2
    t2 = _tan2(m)
    r2 = m[0] ** 2 + m[1] ** 2
    k = (m[0] ** 2 / ax**2 + m[1] ** 2 / ay**2) / r2 if r2 > 0 else mp.mpf(0)
    if name == "ggx":
        return 1 / (mp.pi * ax * ay * cos2 * cos2 * (1 + t2 * k) ** 2)
    if name == "beckmann":
        return mp.exp(-t2 * k) / (mp.pi * ax * ay * cos2 * cos2)
    p = 2 / ax**2 - 2
    return (p + 2) / (2 * mp.pi) * m[2] ** p


def Lambda(name, alpha, w):
    """Smith Lambda: GGX and Beckmann closed forms; Phong by quadrature of its slope marginal."""
    ax, ay = (mp.mpf(a) for a in alpha)
    if w[0] == 0 and w[1] == 0:
        return mp.mpf(0)
    t2 = _tan2(w)
    if name == "ggx":
        return (-1 + mp.sqrt(1 + _alpha_w2(w, ax, ay) * t2)) / 2
    if name == "beckmann":
        a = 1 / mp.sqrt(_alpha_w2(w, ax, ay) * t2)
        return -mp.erfc(a) / 2 + mp.exp(-a * a) / (2 * a * mp.sqrt(mp.pi))
    p = 2 / ax**2 - 2
    a = 1 / mp.sqrt(t2)
    # P2(q) ~ (1 + q^2)^(-(p+3)/2); int_a^inf q P2 is elementary, int_a^inf P2 is taken with
    # q = tan t, i.e. int cos^(p+1) t dt, smooth on [atan a, pi/2]
    t0 = mp.atan(a)
    width = 1 / mp.sqrt(p + 2)
    cuts = sorted({t0, *(min(t0 + width * s, mp.pi / 2) for s in (1, 4, 16)), mp.pi / 2})
    tail_p2 = mp.quad(lambda t: max(mp.cos(t), 0) ** (p + 1), cuts)
    tail_qp2 = (1 + a * a) ** (-(p + 1) / 2) / (p + 1)
    norm = 2 * mp.quad(lambda t: max(mp.cos(t), 0) ** (p + 1),
                       [0, min(width, mp.pi / 2), mp.pi / 2])
    return (tail_qp2 - a * tail_p2) / (a * norm)


def fresnel_walter(c, rel):
    """Walter eq. 22: c = |cos| to the facet, rel = eta_t / eta_i; 1 under TIR."""
    g2 = rel * rel - 1 + c * c
    if g2 < 0:
        return mp.mpf(1)
    g = mp.sqrt(g2)
    return (g - c) ** 2 / (2 * (g + c) ** 2) * (1 + (c * (g + c) - 1) ** 2 / (c * (g - c) + 1) ** 2)


def fresnel_conductor(c, n):
    """Unpolarised reflectance of a conductor of complex index n, from Snell with complex angles."""
    n = mp.mpc(n)
    sin_t = mp.sqrt(1 - c * c) / n
    cos_t = mp.sqrt(1 - sin_t * sin_t)
    rs = (c - n * cos_t) / (c + n * cos_t)
    rp = (n * c - cos_t) / (n * c + cos_t)
    return (abs(rs) ** 2 + abs(rp) ** 2) / 2


def _g2(name, alpha, masking, wi, wo):
    """Smith G2: separable G1 G1, or height-correlated (Heitz 2014): 1/(1 + Li + Lo) for a
    reflected pair, the Beta function B(1 + Li, 1 + Lo) for a transmitted one."""
    li, lo = Lambda(name, alpha, wi), Lambda(name, alpha, wo)
    if masking == "separable":
        return 1 / ((1 + li) * (1 + lo))
    if wi[2] * wo[2] < 0:
        return mp.beta(1 + li, 1 + lo)
    return 1 / (1 + li + lo)


def eval_dielectric(name, alpha, eta, masking, wi, wo, lobes=("reflection", "transmission")):
    """Walter's f_r + f_t (eqs. 20, 21) at 50 digits; 0 at exactly grazing directions."""
    wi, wo = _vec(wi), _vec(wo)
    ci, co = wi[2], wo[2]
    if ci == 0 or co == 0:
        return mp.mpf(0)
    eta = mp.mpf(eta)
    eta_i, eta_o = (mp.mpf(1), eta) if ci > 0 else (eta, mp.mpf(1))
    if ci * co > 0:
        if "reflection" not in lobes:
            return mp.mpf(0)
        s = 1 if ci > 0 else -1
        h = [s * (x + y) for x, y in zip(wi, wo, strict=True)]
    else:
        if "transmission" not in lobes:
            return mp.mpf(0)
        h = [-(eta_i * x + eta_o * y) for x, y in zip(wi, wo, strict=True)]
    n = mp.sqrt(_dot(h, h))
    if n == 0:
        return mp.mpf(0)
    h = [x / n for x in h]
    if h[2] < 0:
        h = [-x for x in h]
    ih, oh = _dot(wi, h), _dot(wo, h)
    if ih * ci <= 0 or oh * co <= 0:
        return mp.mpf(0)
    F = fresnel_walter(abs(ih), eta_o / eta_i)
    g = _g2(name, alpha, masking, wi, wo) * D(name, alpha, h)
    if ci * co > 0:
        return F * g / (4 * abs(ci) * abs(co))
    return (abs(ih) * abs(oh) / (abs(ci) * abs(co)) * eta_o**2 * (1 - F) * g
            / (eta_i * ih + eta_o * oh) ** 2)


def eval_conductor(name, alpha, eta_complex, masking, wi, wo):
    """Microfacet conductor reflection at 50 digits; F = 1 when eta_complex is None."""
    wi, wo = _vec(wi), _vec(wo)
    if wi[2] <= 0 or wo[2] <= 0:
        return mp.mpf(0)
    h = [x + y for x, y in zip(wi, wo, strict=True)]
    n = mp.sqrt(_dot(h, h))
    h = [x / n for x in h]
    F = 1 if eta_complex is None else fresnel_conductor(_dot(wi, h), eta_complex)
    return F * D(name, alpha, h) * _g2(name, alpha, masking, wi, wo) / (4 * wi[2] * wo[2])
