"""Microfacet normal distributions (Beckmann, GGX, Phong) and their registry: D, exact Smith
Lambda and G1, sampling, and what each supports (compiled kernels, visible normals, the
random walk of multiple scattering, its lobe-width scale).

Methods take local-frame unit vectors (..., 3), +z the macro-surface normal, and broadcast
over leading dimensions; alpha_x and alpha_y may be arrays that broadcast the same way.
A direction w below the surface (w.z < 0) is treated through its mirror image (w.z -> |w.z|),
i.e. the surface seen from w's own side, except by the whole-sphere methods the random walk
uses (signed_lambda, projected_area, D_visible, sample_visible_sphere). The scalar formulas of
the compiled kernels are in primitives.py; these are their vectorised versions. scipy is
imported where it is used, so that the registry (DISTRIBUTIONS) imports without it: the CLI
builds its options from it."""

from __future__ import annotations

import math

import numpy as np

from model.bsdf.constants import BECKMANN_CF_FROM, BECKMANN_CF_TERMS, SQRT_PI, Ndf
from model.bsdf.vectors import dot


def beckmann_a_lambda(a: np.ndarray) -> np.ndarray:
    """a * Lambda(a) for the Beckmann Smith function, accurate to ~1e-16 for every a >= 0.

    Lambda(a) = (exp(-a^2) / (a sqrt(pi)) - erfc(a)) / 2 cancels for large a; there
    1 - a sqrt(pi) erfcx(a) = t / (a + t) with t the tail of the erfc continued fraction.
    """
    from scipy.special import erfc

    a = np.asarray(a, dtype=np.float64)
    small = a < BECKMANN_CF_FROM
    a_s = np.where(small, a, 0.0)
    direct = 0.5 * (np.exp(-a_s * a_s) / SQRT_PI - a_s * erfc(a_s))
    a_l = np.where(small, BECKMANN_CF_FROM, a)
    t = np.zeros_like(a_l)
    for k in range(BECKMANN_CF_TERMS, 0, -1):
        t = 0.5 * k / (a_l + t)
    with np.errstate(over="ignore", invalid="ignore"):
        tail = np.exp(-a_l * a_l) * t / (2.0 * SQRT_PI * (a_l + t))
    tail = np.where(np.isfinite(a_l), tail, 0.0)
    return np.where(small, direct, tail)


def beta_half(k: np.ndarray) -> np.ndarray:
    """B(k, 1/2) = sqrt(pi) Gamma(k) / Gamma(k + 1/2), accurate to ~1e-16 for all k > 0.

    scipy's beta loses up to 2e-11 for k in the thousands (Phong at small alpha); there the
    Stirling-type series Gamma(k + 1/2) / Gamma(k) = sqrt(k) exp(-1/(8k) + 1/(192k^3) -
    1/(640k^5) + 17/(14336k^7)) is used instead (k >= 50, error < 1e-16 there).
    """
    from scipy.special import beta

    k = np.asarray(k, dtype=np.float64)
    large = k >= 50.0
    x = 1.0 / np.where(large, k, 50.0)
    ratio = np.sqrt(np.where(large, k, 50.0)) * np.exp(
        x * (-1.0 / 8 + x * x * (1.0 / 192 + x * x * (-1.0 / 640 + x * x * 17.0 / 14336))))
    return np.where(large, SQRT_PI / ratio, beta(np.where(large, 1.0, k), 0.5))


def _positive(alpha, what: str) -> np.ndarray:
    a = np.asarray(alpha, dtype=np.float64)
    if not np.all(np.isfinite(a) & (a > 0)):
        raise ValueError(f"{what} must be finite and > 0, got {alpha!r}")
    return a


def gaussian_slope_scale(alpha: float, t: np.ndarray) -> np.ndarray:
    """Slope length over which D ~ exp(-t^2 / alpha^2) changes by order one at slope t."""
    return 0.5 * alpha**2 / (alpha / np.sqrt(2.0) + t)


class Distribution:
    """Common part of the anisotropic slope-space distributions; subclasses give D and Lambda
    and state what they support in the class attributes below."""

    name = ""
    #: Identity of its scalar formulas in primitives.py (the compiled kernels); None: numpy only.
    kernel: Ndf | None = None
    #: Normal-sampling schemes (microfacet.SAMPLINGS) whose sample() is compiled too.
    compiled_samplings: tuple[str, ...] = ()
    #: Whether it has a visible-normal sampler (sampling='visible', the default when it has).
    visible_sampler = True
    #: Whether the random walk of multiple scattering can walk on it (a Smith slope
    #: distribution with Lambda and visible normals from any direction on the sphere).
    multiple_scattering = False

    def __init__(self, alpha_x, alpha_y=None):
        self.alpha_x = _positive(alpha_x, "alpha")
        self.alpha_y = self.alpha_x if alpha_y is None else _positive(alpha_y, "alpha_y")

    def __repr__(self) -> str:
        return f"{type(self).__name__}(alpha_x={self.alpha_x}, alpha_y={self.alpha_y})"

    def scaled(self, k) -> Distribution:
        """The same distribution with both roughnesses multiplied by k (array or scalar)."""
        return type(self)(self.alpha_x * k, self.alpha_y * k)

    def _tangent_q(self, w: np.ndarray) -> np.ndarray:
        """(alpha_x w_x)^2 + (alpha_y w_y)^2 = (alpha tan theta cos theta)^2 along w."""
        return (self.alpha_x * w[..., 0]) ** 2 + (self.alpha_y * w[..., 1]) ** 2

    def _slope_q(self, m: np.ndarray) -> np.ndarray:
        """(m_x / alpha_x)^2 + (m_y / alpha_y)^2."""
        return (m[..., 0] / self.alpha_x) ** 2 + (m[..., 1] / self.alpha_y) ** 2

    def cos_lambda(self, w: np.ndarray) -> np.ndarray:
        """|w.z| Lambda(w): finite (alpha_w sin / 2 for GGX) even at exactly grazing w."""
        raise NotImplementedError

    def D(self, m: np.ndarray) -> np.ndarray:
        """Microfacet normal density D(m) per unit solid angle (0 for m.z <= 0)."""
        raise NotImplementedError

    def Lambda(self, w: np.ndarray) -> np.ndarray:
        """Smith Lambda(w); +inf at exactly grazing w."""
        c = np.abs(w[..., 2])
        cl = self.cos_lambda(w)
        with np.errstate(over="ignore"):  # c ~ 1e-320: Lambda beyond 1.8e308 is inf
            return np.where(c > 0, cl / np.where(c > 0, c, 1.0), np.inf)

    def G1(self, w: np.ndarray, m: np.ndarray) -> np.ndarray:
        """Smith masking G1(w, m) = chi+(w.m / w.z) / (1 + Lambda(w))."""
        c = np.abs(w[..., 2])
        facing = dot(w, m) * w[..., 2] > 0
        den = c + self.cos_lambda(w)
        return np.where(facing & (den > 0), c / np.where(den > 0, den, 1.0), 0.0)

    def pdf_normal(self, m: np.ndarray) -> np.ndarray:
        """Density of sample_normal over solid angle: D(m) max(m.z, 0)."""
        return self.D(m) * np.maximum(m[..., 2], 0.0)

    def pdf_visible(self, w: np.ndarray, m: np.ndarray) -> np.ndarray:
        """Density of sample_visible: G1(w, m) max(0, w.m) D(m) / w.z (w taken on its side)."""
        w = _upper(w)
        c = w[..., 2]
        wm = dot(w, m)
        den = c + self.cos_lambda(w)
        ok = (wm > 0) & (den > 0)
        return np.where(ok, wm * self.D(m) / np.where(ok, den, 1.0), 0.0)

    def sample_normal(self, u1: np.ndarray, u2: np.ndarray) -> np.ndarray:
        """Normals with density D(m) m.z over solid angle, from uniforms u1, u2 in [0, 1)."""
        r = self._unit_slope_radius(np.asarray(u1, dtype=np.float64))
        phi = 2.0 * math.pi * np.asarray(u2, dtype=np.float64)
        return _normal_from_slopes(self.alpha_x * r * np.cos(phi), self.alpha_y * r * np.sin(phi))

    def sample_visible(self, w: np.ndarray, u1: np.ndarray, u2: np.ndarray) -> np.ndarray:
        """Normals distributed as the visible normals D_w(m) seen from w (Heitz 2014/2018)."""
        raise ValueError(f"{self.name} has no visible-normal sampler; use sampling='walter'")

    def _unit_slope_radius(self, u: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    @property
    def default_sampling(self) -> str:
        """The normal-sampling scheme used when none is named: visible normals if it has them."""
        return "visible" if self.visible_sampler else "walter"

    @staticmethod
    def slope_scale(alpha: float, t: np.ndarray) -> np.ndarray:
        """Local length scale, in slope space, over which D changes by order one at slope t
        (how fine a quadrature of the lobe must be)."""
        raise NotImplementedError

    # --- the whole sphere (the random walk) -------------------------------------------------

    def signed_lambda(self, w: np.ndarray) -> np.ndarray:
        """Smith Lambda(w) with its sign: >= 0 upward, Lambda(-w) = -1 - Lambda(w) <= -1
        downward; +inf exactly horizontal."""
        z = w[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            up = self.cos_lambda(w) / np.abs(z)
        up = np.where(np.abs(z) > 0.0, up, np.inf)
        return np.where(z >= 0.0, up, -1.0 - up)

    def projected_area(self, w: np.ndarray) -> np.ndarray:
        """Integral of <w, m>+ D(m) dm = w_z (1 + Lambda(w)), for w anywhere on the sphere."""
        return np.maximum(w[..., 2], 0.0) + self.cos_lambda(w)

    def D_visible(self, w: np.ndarray, m: np.ndarray) -> np.ndarray:
        """Normals visible from w (any direction): <w,m>+ D(m) / projected_area(w)."""
        cos = np.maximum(np.sum(w * m, axis=-1), 0.0)
        area = self.projected_area(w)
        with np.errstate(divide="ignore", invalid="ignore"):
            out = cos * self.D(m) / area
        return np.where(area > 0.0, out, 0.0)

    def sample_visible_sphere(self, w: np.ndarray, u1: np.ndarray, u2: np.ndarray) -> np.ndarray:
        """A normal m ~ D_visible(w, .) for w anywhere on the sphere (the walk's sampler)."""
        raise ValueError(f"{self.name} has no visible-normal sampler")


def _upper(w: np.ndarray) -> np.ndarray:
    """w mirrored to the upper hemisphere (z -> |z|)."""
    return np.concatenate([w[..., :2], np.abs(w[..., 2:3])], axis=-1)


def _normal_from_slopes(sx: np.ndarray, sy: np.ndarray) -> np.ndarray:
    """Unit normal (-sx, -sy, 1) / |.| of a facet with slopes (sx, sy)."""
    inv = 1.0 / np.sqrt(1.0 + sx * sx + sy * sy)
    return np.stack([-sx * inv, -sy * inv, inv], axis=-1)


def _stretched_frame(w: np.ndarray, ax, ay):
    """cos, sin of theta and cos, sin of phi of w stretched to unit roughness (ax wx, ay wy, wz)."""
    w = _upper(w)
    sx = ax * w[..., 0]
    sy = ay * w[..., 1]
    r = np.hypot(sx, sy)
    n = np.hypot(r, w[..., 2])
    has_phi = r > 0
    r1 = np.where(has_phi, r, 1.0)
    return w[..., 2] / n, r / n, np.where(has_phi, sx / r1, 1.0), np.where(has_phi, sy / r1, 0.0)


class GGX(Distribution):
    """Trowbridge-Reitz (GGX) distribution, anisotropic, with its closed-form Smith Lambda."""

    name = "ggx"
    kernel = Ndf.GGX
    compiled_samplings = ("visible", "walter")
    multiple_scattering = True

    def D(self, m):
        mz = m[..., 2]
        den = mz * mz + self._slope_q(m)
        return np.where(mz > 0, 1.0 / (math.pi * self.alpha_x * self.alpha_y * den * den), 0.0)

    def cos_lambda(self, w):
        q = self._tangent_q(w)
        c = np.abs(w[..., 2])
        return q / (2.0 * (np.sqrt(c * c + q) + c))

    def _unit_slope_radius(self, u):
        return np.sqrt(u / (1.0 - u))

    @staticmethod
    def slope_scale(alpha, t):
        """D ~ (alpha^2 + t^2)^-2: alpha / 2 at the peak, t / 4 in the tail."""
        return (alpha**2 + t**2) / (4.0 * t + 2.0 * alpha)

    def sample_visible(self, w, u1, u2):
        return self._visible(_upper(w), u1, u2, _length)

    def sample_visible_sphere(self, w, u1, u2):
        """Heitz 2018 in the stretched frame; for w below the horizon the visible part of the
        unit hemisphere projects onto the same disk region, t2 in [-v_z sqrt(1 - t1^2),
        sqrt(1 - t1^2)], sampled by the same linear warp of a uniform disk point."""
        return self._visible(w, u1, u2, _linalg_length)

    def _visible(self, w, u1, u2, length):
        """Visible normals seen from w, vectors normalised by length(v) (..., 1): the two
        samplers round their normalisations differently (einsum and linalg.norm differ in the
        last ulp), each kept so that its numbers, and the walks' random streams, stay put."""
        u1 = np.asarray(u1, dtype=np.float64)
        u2 = np.asarray(u2, dtype=np.float64)
        vh = np.stack([self.alpha_x * w[..., 0], self.alpha_y * w[..., 1], w[..., 2]], axis=-1)
        vh = vh / length(vh)
        lensq = vh[..., 0] ** 2 + vh[..., 1] ** 2
        has = lensq > 0
        inv = np.where(has, 1.0 / np.sqrt(np.where(has, lensq, 1.0)), 0.0)
        t1 = np.stack([np.where(has, -vh[..., 1] * inv, 1.0),
                       np.where(has, vh[..., 0] * inv, 0.0), np.zeros_like(lensq)], axis=-1)
        t2 = np.cross(vh, t1)
        r = np.sqrt(u1)
        phi = 2.0 * math.pi * u2
        p1 = r * np.cos(phi)
        p2 = r * np.sin(phi)
        s = 0.5 * (1.0 + vh[..., 2])
        p2 = (1.0 - s) * np.sqrt(np.maximum(1.0 - p1 * p1, 0.0)) + s * p2
        p3 = np.sqrt(np.maximum(1.0 - p1 * p1 - p2 * p2, 0.0))
        nh = p1[..., None] * t1 + p2[..., None] * t2 + p3[..., None] * vh
        ne = np.stack([self.alpha_x * nh[..., 0], self.alpha_y * nh[..., 1],
                       np.maximum(nh[..., 2], 0.0)], axis=-1)
        return ne / length(ne)


def _length(v: np.ndarray) -> np.ndarray:
    """|v| along the last axis, kept as a length-1 axis (einsum: the faster)."""
    return np.sqrt(dot(v, v))[..., None]


def _linalg_length(v: np.ndarray) -> np.ndarray:
    """|v| along the last axis by np.linalg.norm, kept as a length-1 axis."""
    return np.linalg.norm(v, axis=-1, keepdims=True)


class Beckmann(Distribution):
    """Beckmann distribution, anisotropic, with the exact erfc-based Smith Lambda."""

    name = "beckmann"
    kernel = Ndf.BECKMANN
    #: Its visible-normal sampler needs erfinv, which numba lacks: Walter's only.
    compiled_samplings = ("walter",)
    multiple_scattering = True
    slope_scale = staticmethod(gaussian_slope_scale)

    #: Newton-bisection iterations of the visible-slope inversion (converges to ~1e-15).
    VISIBLE_ITERATIONS = 40

    def D(self, m):
        mz = m[..., 2]
        pos = mz > 0
        mz1 = np.where(pos, mz, 1.0)
        expo = -self._slope_q(m) / (mz1 * mz1) - 4.0 * np.log(mz1)
        return np.where(pos, np.exp(expo) / (math.pi * self.alpha_x * self.alpha_y), 0.0)

    def cos_lambda(self, w):
        r = np.sqrt(self._tangent_q(w))
        c = np.abs(w[..., 2])
        with np.errstate(divide="ignore"):
            a = np.where(r > 0, c / np.where(r > 0, r, 1.0), np.inf)
        return r * beckmann_a_lambda(a)

    def _unit_slope_radius(self, u):
        return np.sqrt(-np.log1p(-u))

    def sample_visible(self, w, u1, u2):
        u1 = np.asarray(u1, dtype=np.float64)
        u2 = np.asarray(u2, dtype=np.float64)
        cos_t, sin_t, cos_p, sin_p = _stretched_frame(w, self.alpha_x, self.alpha_y)
        x, y = self._visible_unit_slopes(cos_t, sin_t, u1, u2)
        sx = cos_p * x - sin_p * y
        sy = sin_p * x + cos_p * y
        return _normal_from_slopes(self.alpha_x * sx, self.alpha_y * sy)

    def _visible_unit_slopes(self, cos_t, sin_t, u1, u2):
        """Slopes of unit-roughness visible normals for incidence theta along +x.

        The CDF of the x slope, in the variable b = erf(x), is
        C(b) ~ cos_t (1 + b) + sin_t exp(-erfinv(b)^2) / sqrt(pi), for b up to erf(cot_t);
        it is inverted by safeguarded Newton iteration in b (after Jakob's Mitsuba sampler).
        """
        from scipy.special import erfc, erfinv

        with np.errstate(divide="ignore", invalid="ignore"):
            cot_t = np.where(sin_t > 0, cos_t / np.where(sin_t > 0, sin_t, 1.0), np.inf)
        # both sides multiplied by cos_t so that grazing incidence (tan = inf) stays finite
        erf_cot = 1.0 - erfc(cot_t)
        norm = cos_t * (1.0 + erf_cot) + sin_t * np.exp(-cot_t * cot_t) / SQRT_PI
        lo = np.full_like(u1, -1.0)
        hi = erf_cot.copy()
        b = 0.5 * (lo + hi)
        target = u1 * norm
        for _ in range(self.VISIBLE_ITERATIONS):
            x = erfinv(b)
            value = cos_t * (1.0 + b) + sin_t * np.exp(-x * x) / SQRT_PI - target
            deriv = cos_t - x * sin_t  # d/db, using d exp(-x^2)/db = -x sqrt(pi)
            hi = np.where(value > 0, b, hi)
            lo = np.where(value > 0, lo, b)
            with np.errstate(divide="ignore", invalid="ignore"):
                step = b - value / deriv
            inside = np.isfinite(step) & (step > lo) & (step < hi)
            b = np.where(inside, step, 0.5 * (lo + hi))
        x = erfinv(np.clip(b, -1.0, 1.0))
        y = erfinv(2.0 * u2 - 1.0)
        return np.where(np.isfinite(x), x, 0.0), np.where(np.isfinite(y), y, 0.0)

    def sample_visible_sphere(self, w, u1, u2):
        """By stretching to alpha = 1 (beckmann_sphere: a log-CDF inversion that holds below
        the horizon too, where sample_visible's erf-variable one does not)."""
        from model.bsdf.beckmann_sphere import beckmann_visible_unit

        ax, ay = self.alpha_x, self.alpha_y
        v = np.stack([ax * w[..., 0], ay * w[..., 1], w[..., 2]], axis=-1)
        v /= np.linalg.norm(v, axis=-1, keepdims=True)
        n = beckmann_visible_unit(v, u1, u2)
        m = np.stack([ax * n[..., 0], ay * n[..., 1], np.maximum(n[..., 2], 0.0)], axis=-1)
        return m / np.linalg.norm(m, axis=-1, keepdims=True)


class Phong(Distribution):
    """Phong distribution, exponent p = 2 / alpha^2 - 2 (Walter's mapping from Beckmann alpha).

    alpha is the Beckmann-equivalent roughness. Lambda and G1 are Phong's own exact Smith
    functions (closed form through the incomplete beta function), not Beckmann's, which
    Walter used as an approximation and which breaks the projected-area identity by up to
    26 % at alpha 0.9. For p <= -1 (alpha >= sqrt 2) the mean slope is infinite and so is
    Lambda: every direction but the normal is fully masked. Isotropic only; no visible-normal
    sampler (use sampling='walter'), so no random walk either.
    """

    name = "phong"
    visible_sampler = False
    #: Beckmann's (Phong is its close cousin).
    slope_scale = staticmethod(gaussian_slope_scale)

    def __init__(self, alpha_x, alpha_y=None):
        super().__init__(alpha_x, alpha_y)
        if alpha_y is not None and not np.array_equal(self.alpha_x, self.alpha_y):
            raise ValueError("phong is isotropic: alpha must be a single value")
        self.exponent = 2.0 / self.alpha_x**2 - 2.0

    def D(self, m):
        mz = m[..., 2]
        pos = mz > 0
        p = self.exponent
        # log m.z from the small tangential part near the pole: p may be 2e8 at alpha = 1e-4
        r2 = m[..., 0] ** 2 + m[..., 1] ** 2
        log_mz = np.where(mz > 0.5, np.log1p(-np.minimum(r2 / (1.0 + np.abs(mz)), 0.5)),
                          np.log(np.where(pos, mz, 1.0)))
        with np.errstate(over="ignore"):
            val = (p + 2.0) / (2.0 * math.pi) * np.exp(p * log_mz)
        return np.where(pos, val, 0.0)

    def cos_lambda(self, w):
        """|w.z| Lambda = r^(p+2) / ((p+1) B) - |w.z| I_{r^2}((p+2)/2, 1/2) / 2, r = |w_xy|.

        From Lambda(a) = (1/a) int_a^inf (q - a) P2(q) dq with the Phong slope marginal
        P2(q) = (1 + q^2)^(-(p+3)/2) / B((p+2)/2, 1/2).
        """
        from scipy.special import betainc

        p = self.exponent
        c2 = np.minimum(w[..., 2] ** 2, 1.0)
        r2 = 1.0 - c2  # from c2 so that r2 -> 1 keeps its 1e-18 (matters when p ~ 1e8)
        k = 0.5 * (p + 2.0)
        near_pole = c2 > 0.5
        r2 = np.where(near_pole, np.minimum(w[..., 0] ** 2 + w[..., 1] ** 2, 1.0), r2)
        log_r2 = np.where(near_pole, np.log(np.where(r2 > 0, r2, 1.0)),
                          np.log1p(-np.minimum(c2, 0.5)))
        # I_{r2}(k, 1/2) = 1 - I_{c2}(1/2, k): take whichever side is small (the accurate one)
        direct = betainc(k, 0.5, r2)
        other = ~(direct < 0.5)  # betainc returns at once at x = 0: asked only where taken
        inc = np.where(other, 1.0 - betainc(0.5, k, np.where(other, c2, 0.0)), direct)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            finite = np.exp(k * log_r2) / ((p + 1.0) * beta_half(k)) - 0.5 * np.sqrt(c2) * inc
        return np.where(r2 == 0, 0.0, np.where(p > -1.0, np.maximum(finite, 0.0), np.inf))

    def sample_normal(self, u1, u2):
        u1 = np.asarray(u1, dtype=np.float64)
        phi = 2.0 * math.pi * np.asarray(u2, dtype=np.float64)
        # 1 - u1 is uniform in (0, 1]; u1 = 1 is the horizon normal (log cos = -inf), taken
        # explicitly rather than through log1p(-1)
        top = u1 < 1.0
        log_cos = np.where(top, np.log1p(-np.where(top, u1, 0.0)), -np.inf) / (self.exponent
                                                                                 + 2.0)
        cos_t = np.exp(log_cos)
        sin_t = np.sqrt(-np.expm1(2.0 * log_cos))
        return np.stack([sin_t * np.cos(phi), sin_t * np.sin(phi), cos_t], axis=-1)


#: Every distribution by name: the one list the models, the bench, the fits and the CLI use.
DISTRIBUTIONS = {cls.name: cls for cls in (Beckmann, GGX, Phong)}
DISTRIBUTION_NAMES = tuple(DISTRIBUTIONS)
#: Those with compiled kernels, and those the random walk (multiple scattering) can walk on.
WITH_KERNELS = tuple(name for name, cls in DISTRIBUTIONS.items() if cls.kernel is not None)
WALKABLE = tuple(name for name, cls in DISTRIBUTIONS.items() if cls.multiple_scattering)


def make_distribution(name: str, alpha) -> Distribution:
    """Build a distribution by name: 'beckmann', 'ggx' or 'phong'; alpha a float or a pair."""
    try:
        cls = DISTRIBUTIONS[name]
    except (KeyError, TypeError):
        raise ValueError(
            f"distribution must be one of {sorted(DISTRIBUTIONS)}, got {name!r}") from None
    if isinstance(alpha, (tuple, list)):
        if len(alpha) != 2:
            raise ValueError(f"alpha must be a float or (alpha_x, alpha_y), got {alpha!r}")
        return cls(alpha[0], alpha[1])
    return cls(alpha)
