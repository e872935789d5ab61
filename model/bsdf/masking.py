"""Smith masking-shadowing G2 of a pair of directions: separable (Walter) or height-correlated.

Everything is written divided by the two cosines, G2 / (|cos i| |cos o|), from the finite
quantities |cos| and |cos| Lambda, so grazing directions give finite limits instead of 0/0.

Height-correlated (Heitz 2014, JCGT 3(2), sec. 6): a point at height h with height CDF u = C(h)
is unmasked along an upward direction with probability u^Lambda and along a downward one with
(1 - u)^Lambda. Reflection has both directions above: G2 = int u^(Li + Lo) du = 1/(1 + Li + Lo).
Transmission has one above and one below the same point: G2 = int u^Li (1 - u)^Lo du
= B(1 + Li, 1 + Lo), the Beta function, computed in log form stable for Lambda up to 1e100.
These are the vectorised versions of primitives.py's scalar g2_over_cosines and log_beta."""

from __future__ import annotations

import numpy as np

from model.bsdf.constants import HALF_LOG_2PI, STIRLING_FROM, STIRLING_TERMS, Masking, enum_names

#: Every masking form by name: the one list the models, the bench, the fits and the CLI use.
MASKINGS = enum_names(Masking)


def check_masking(masking: str) -> str:
    """Return masking if it names a supported scheme, else raise a ValueError naming it."""
    if masking not in MASKINGS:
        raise ValueError(f"masking must be one of {MASKINGS}, got {masking!r}")
    return masking


def masking_kind(masking: str) -> Masking:
    """The kernels' identity of a masking form named in MASKINGS."""
    return Masking[check_masking(masking).upper()]


def g2_over_cosines(
    masking: str, ci: np.ndarray, co: np.ndarray, li: np.ndarray, lo: np.ndarray,
    transmitted: np.ndarray | bool = False,
) -> np.ndarray:
    """G2(i, o) / (ci co) from ci = |cos i|, co = |cos o| and li, lo = |cos| Lambda.

    separable: G1(i) G1(o) = ci co / ((ci + li)(co + lo));
    correlated reflection: 1 / (1 + Lambda_i + Lambda_o) = ci co / (ci co + co li + ci lo);
    correlated transmission (transmitted True: wi, wo on opposite sides): B(1 + Li, 1 + Lo).
    """
    ci, co, li, lo = (np.asarray(a, dtype=np.float64) for a in (ci, co, li, lo))
    masked = np.isinf(li) | np.isinf(lo)  # infinite mean slope: fully masked, G2 = 0
    li, lo = np.where(masked, 0.0, li), np.where(masked, 0.0, lo)
    if masking == "separable":
        return np.where(masked, 0.0, _reciprocal((ci + li) * (co + lo)))
    reflected = np.where(masked, 0.0, _reciprocal(ci * co + co * li + ci * lo))
    if not np.any(transmitted):
        return reflected
    return np.where(transmitted, beta_over_cosines(ci, co, li, lo), reflected)


def _reciprocal(den: np.ndarray) -> np.ndarray:
    """1 / den for den >= 0, +inf where den == 0 (both directions exactly grazing, where
    G2 / (cos cos) truly diverges), without a division by zero."""
    return np.divide(1.0, den, out=np.full(np.shape(den), np.inf), where=den > 0)


def beta_over_cosines(ci: np.ndarray, co: np.ndarray, li: np.ndarray, lo: np.ndarray) -> np.ndarray:
    """B(1 + li/ci, 1 + lo/co) / (ci co): height-correlated transmission G2 over the cosines.

    0 where either Lambda is infinite (fully masked); finite for ci, co > 0 however large
    Lambda is (B then decays like Lambda^-(1 + other Lambda))."""
    ci, co, li, lo = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in
                                           (ci, co, li, lo)))
    live = (ci > 0) & (co > 0) & np.isfinite(li) & np.isfinite(lo)
    one = np.ones_like(ci)
    ci, co = np.where(live, ci, one), np.where(live, co, one)
    p = 1.0 + np.where(live, li, 0.0) / ci
    q = 1.0 + np.where(live, lo, 0.0) / co
    with np.errstate(over="ignore"):  # both cosines ~1e-300: the true value exceeds 1.8e308
        return np.where(live, np.exp(log_beta(p, q) - np.log(ci) - np.log(co)), 0.0)


def stirling_correction(x: np.ndarray) -> np.ndarray:
    """log Gamma(x) - ((x - 1/2) log x - x + log sqrt(2 pi)), for x >= STIRLING_FROM."""
    r = 1.0 / x
    r2 = r * r
    s = np.zeros_like(r)
    for c in reversed(STIRLING_TERMS):
        s = s * r2 + c
    return s * r


def log_beta(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """log B(p, q) for p, q >= 1 to a few ulp of the largest term, for arguments up to 1e300.

    Never subtracts two large log Gammas: with a = min, b = max,
    both >= 10: log sqrt(2 pi) - log(b)/2 + corr + (a - 1/2) log(a/(a+b)) + b log1p(-a/(a+b));
    only b >= 10: log Gamma(a) + corr + a - a log(a+b) + (b - 1/2) log1p(-a/(a+b));
    both < 10: log(Gamma(a) Gamma(b) / Gamma(a+b)), all moderate numbers.
    """
    from scipy.special import gamma, gammaln  # here: the registry MASKINGS imports without it

    a, b = np.minimum(p, q), np.maximum(p, q)
    s = a + b
    frac = a / s
    big_a = np.maximum(a, STIRLING_FROM)
    big_b = np.maximum(b, STIRLING_FROM)
    small_a, small_b = np.minimum(a, STIRLING_FROM), np.minimum(b, STIRLING_FROM)
    corr_b = stirling_correction(big_b) - stirling_correction(np.maximum(s, STIRLING_FROM))
    both_big = (HALF_LOG_2PI - 0.5 * np.log(b) + stirling_correction(big_a) + corr_b
                + (a - 0.5) * np.log(frac) + b * np.log1p(-frac))
    one_big = gammaln(small_a) + corr_b + a - a * np.log(s) + (b - 0.5) * np.log1p(-frac)
    both_small = np.log(gamma(small_a) * (gamma(small_b) / gamma(small_a + small_b)))
    return np.where(a >= STIRLING_FROM, both_big, np.where(b >= STIRLING_FROM, one_big,
                                                           both_small))
