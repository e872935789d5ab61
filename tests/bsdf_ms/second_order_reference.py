"""An independent order 2 of the random walk on a Smith microsurface (Heitz et al. 2016) for one
direction pair of a glass lit from air: nested adaptive scipy quadrature over the first event's
outgoing direction of both events' phase functions times the expectation over both heights
(derived here in closed form); its own phase functions, visible areas and height integrals, D,
Lambda and Fresnel from energy_reference. Used by tests/bsdf_ms/test_ms_dark_tail.py;
docs/multiple-scattering.md, "The dark tail".

Order 2 of f |cos o| is the sum over the first event's lobes (reflected: w1 anywhere in the
medium above; transmitted: w1 in the glass) of the integral over w1 of p1(wi -> w1) H p2(-d1 ->
wo), d1 = w1 in the frame of its side (the glass frame is the world mirrored in z, its index
ratio 1 / eta). With uniform heights u = C1(h) (the BSDF does not depend on P1): the first
height has density a0 u^(a0 - 1), a0 = 1 + Lambda(wi); a ray travelling up (its Lambda l > 0)
from u1 meets the surface next at u2 in (u1, 1) with density l u1^l u2^(-l - 1), one
travelling down (m = 1 + Lambda(-d1)) at u2 in (0, u1) with density m u2^(m - 1) / u1^m; wo
escapes from u2 with u2^Lambda(wo) on the side it leaves from, and the other side's CDF is
1 - u2.
"""
from __future__ import annotations

import math

import numpy as np
from scipy import integrate, optimize
from scipy.special import betaln, digamma

from tests.bsdf_ms.energy_reference import fresnel, lam, ndf

#: Relative accuracy asked of every adaptive quadrature, and the subintervals each may use.
EPSREL = 1e-7
LIMIT = 400
#: Equal panels in w1's polar angle (over the lobe's range) and azimuth that every quadrature
#: starts from, so that no narrow feature (a Fresnel kink's cone) falls between its first nodes.
POLAR_PANELS = 16
AZIMUTH_PANELS = 24
#: Grid (polar x azimuth) on which the integrand's peaks are looked for before refining them.
PEAK_GRID = (121, 240)


def _flip(w: np.ndarray) -> np.ndarray:
    return np.array([w[0], w[1], -w[2]])


def _lambda(name: str, alpha: float, w: np.ndarray) -> float:
    """Lambda of an upward w (0 at the normal, where energy_reference's formula is 0/0)."""
    return 0.0 if math.hypot(w[0], w[1]) == 0.0 else float(lam(name, alpha, alpha, w))


def _ndf(name: str, alpha: float, h: np.ndarray) -> float:
    """D of the unit normal h (h_z > 0)."""
    t = math.acos(min(1.0, h[2]))
    return float(ndf(name, alpha, alpha, t, math.atan2(h[1], h[0])))


def _scaled_area(name: str, alpha: float, w: np.ndarray) -> tuple[float, float]:
    """The projected area of w anywhere, integral of <w, m>+ D(m) dm, as (factor, Lambda
    part): |w_z| (1 + Lambda(w)) above the horizon (part 1 + Lambda), |w_z| Lambda(-w) below
    (part Lambda(-w), which the height integrals carry too: kept apart so that it cancels)."""
    if w[2] > 0.0:
        return w[2], 1.0 + _lambda(name, alpha, w)
    return -w[2], _lambda(name, alpha, -w)


def _reflect_phase(name: str, alpha: float, el: float, w_in: np.ndarray, w_out: np.ndarray
                   ) -> float:
    """F D(h) / 4: the reflection phase function times the projected area of w_in (one side's
    frame, index ratio el)."""
    h = w_in + w_out
    norm = np.linalg.norm(h)
    if norm == 0.0 or h[2] <= 0.0:
        return 0.0
    h = h / norm
    c = float(w_in @ h)
    if c <= 0.0:
        return 0.0
    return fresnel(c, el) * _ndf(name, alpha, h) / 4.0


def _transmit_phase(name: str, alpha: float, el: float, w_in: np.ndarray, w_out: np.ndarray
                    ) -> float:
    """(1 - F) D(h) <w_in, h> el^2 |<w_out, h>| / (<w_in, h> + el <w_out, h>)^2: the
    transmission phase function times the projected area of w_in; w_out points into the other
    medium."""
    h = -(w_in + el * w_out)
    norm = np.linalg.norm(h)
    if norm == 0.0:
        return 0.0
    h = h / norm if h[2] > 0.0 else -h / norm
    ci, co = float(w_in @ h), float(w_out @ h)
    if ci <= 0.0 or co >= 0.0:
        return 0.0
    return ((1.0 - fresnel(ci, el)) * _ndf(name, alpha, h) * ci * el * el * -co
            / (ci + el * co) ** 2)


def _beta_quotient(p1: float, p2: float, q: float) -> float:
    """(B(p1, q) - B(p2, q)) / (p1 - p2), by the derivative B (psi(p) - psi(p + q)) where the
    two nearly cancel."""
    if abs(p1 - p2) > 1e-5 * max(p1, p2):
        return (math.exp(betaln(p1, q)) - math.exp(betaln(p2, q))) / (p1 - p2)
    p = 0.5 * (p1 + p2)
    return math.exp(betaln(p, q)) * (digamma(p) - digamma(p + q))


def _heights_up(a0: float, up: float, transmitted: bool, own: float | None,
                other: float | None) -> float:
    """H / l for a first direction travelling up in its side's frame (Lambda l = up), wo
    escaping on d1's side (own: its Lambda) or through the other side (other).
    Reflected first (u2 in (u1, 1), then u1): own a0 / ((a0 + l)(a0 + own)), other
    a0 B(a0, other + 1) / (a0 + l). Transmitted first (glass CDF v = 1 - u): own
    a0 (B(a0, l + 1) - B(a0, own + 1)) / (own - l); never other, as no phase function refracts
    a ray travelling away from the interface in the glass back out."""
    if not transmitted:
        if own is not None:
            return a0 / ((a0 + up) * (a0 + own))
        return a0 * math.exp(betaln(a0, other + 1.0)) / (a0 + up)
    return -a0 * _beta_quotient(up + 1.0, own + 1.0, a0)


def _heights_down(a0: float, down: float, own: float | None, other: float | None) -> float:
    """H for a first direction reflected downward (u2 in (0, u1) with density
    m u2^(m - 1) / u1^m, m = down): own a0 m / ((m + own)(a0 + own)), other (through the
    glass) a0 m (B(m, other + 1) - B(a0, other + 1)) / (a0 - m)."""
    if own is not None:
        return a0 * down / ((down + own) * (a0 + own))
    return -a0 * down * _beta_quotient(down, a0, other + 1.0)


class SecondOrder:
    """Order 2 of f |cos o| from wi (above) to wo of a glass (eta, light from air), slopes
    `name` with roughness alpha (isotropic)."""

    def __init__(self, name: str, alpha: float, eta: float, wi, wo):
        self.name, self.alpha, self.eta = name, float(alpha), eta
        self.wi = np.asarray(wi, float) / np.linalg.norm(wi)
        self.wo = np.asarray(wo, float) / np.linalg.norm(wo)
        if self.wi[2] <= 0.0:
            raise ValueError("wi must be above the surface")
        self.a0 = 1.0 + _lambda(name, alpha, self.wi)
        self.area_i = self.wi[2] * self.a0
        # wo's escape Lambda on its own side (its frame's upward image)
        self.lam_wo = _lambda(name, alpha, self.wo if self.wo[2] > 0.0 else _flip(self.wo))

    def _phase(self, reflect: bool, outside: bool, w_in, w_out) -> float:
        """Phase function of an event on the air (outside) or glass side times w_in's area."""
        el = self.eta if outside else 1.0 / self.eta
        if reflect:
            return _reflect_phase(self.name, self.alpha, el, w_in, w_out)
        return _transmit_phase(self.name, self.alpha, el, w_in, w_out)

    def integrand(self, transmitted: bool, theta: float, phi: float) -> float:
        """The integrand over w1's polar angle and azimuth (sin theta included) of the first
        event's reflected or transmitted lobe."""
        s = math.sin(theta)
        w1 = np.array([s * math.cos(phi), s * math.sin(phi), math.cos(theta)])
        if w1[2] == 0.0 or (transmitted and w1[2] > 0.0):
            return 0.0
        first = self._phase(not transmitted, True, self.wi, w1) / self.area_i
        if first == 0.0:
            return 0.0
        d1 = _flip(w1) if transmitted else w1  # in the frame of the side it travels in
        wo = _flip(self.wo) if transmitted else self.wo
        own = wo[2] > 0.0  # wo leaves on d1's side
        second = self._phase(own, not transmitted, -d1, wo)
        if second == 0.0:
            return 0.0
        factor, part = _scaled_area(self.name, self.alpha, -d1)
        escape = (self.lam_wo, None) if own else (None, self.lam_wo)
        if d1[2] > 0.0:  # the area is l d1_z, and H carries l
            return s * first * second * _heights_up(self.a0, part, transmitted, *escape) / factor
        return s * first * second * _heights_down(self.a0, part, *escape) / (factor * part)

    def _polar_breaks(self, transmitted: bool) -> list[float]:
        """Polar angles of w1 where Lambda changes branch (the horizon) and where a phase
        function's support ends (its facet normal reaches the horizon): the first reflection's
        at w1_z = -wi_z, the second's at d1_z = wo_z (reflected) or el wo_z (transmitted)."""
        z = [0.0] if transmitted else [0.0, -self.wi[2]]
        wo = _flip(self.wo) if transmitted else self.wo
        el = 1.0 / self.eta if transmitted else self.eta
        d1_z = wo[2] if wo[2] > 0.0 else el * wo[2]
        z.append(-d1_z if transmitted else d1_z)
        return [math.acos(c) for c in z if -1.0 < c < 1.0]

    def peaks(self, transmitted: bool, count: int = 4) -> list[tuple[float, float]]:
        """(theta, phi) of the integrand's largest local maxima: found on PEAK_GRID, refined
        by Nelder-Mead on its logarithm."""
        lo = 0.5 * math.pi if transmitted else 0.0
        theta = np.linspace(lo, math.pi, PEAK_GRID[0] + 2)[1:-1]
        phi = np.linspace(0.0, 2.0 * math.pi, PEAK_GRID[1], endpoint=False)
        grid = np.array([[self.integrand(transmitted, t, p) for p in phi] for t in theta])
        with np.errstate(divide="ignore"):
            log_grid = np.log(grid)
        padded = np.pad(log_grid, ((1, 1), (0, 0)), constant_values=-np.inf)
        neighbours = [np.roll(padded, (i, j), axis=(0, 1))[1:-1]
                      for i in (-1, 0, 1) for j in (-1, 0, 1) if (i, j) != (0, 0)]
        local = np.isfinite(log_grid) & np.all([log_grid >= n for n in neighbours], axis=0)
        rows, cols = np.nonzero(local)
        order = np.argsort(log_grid[rows, cols])[::-1][:count]

        def cost(x):
            v = self.integrand(transmitted, min(max(x[0], lo), math.pi), x[1])
            return -math.log(v) if v > 0.0 else 1e300

        found: list[tuple[float, float]] = []
        for r, c in zip(rows[order], cols[order], strict=True):
            best = optimize.minimize(cost, [theta[r], phi[c]], method="Nelder-Mead",
                                     options={"xatol": 1e-9, "fatol": 1e-12, "maxiter": 4000})
            peak = (min(max(best.x[0], lo), math.pi), best.x[1] % (2.0 * math.pi))
            if all(math.dist(peak, other) > 1e-6 for other in found):
                found.append(peak)
        return found

    def lobe(self, transmitted: bool) -> tuple[float, float]:
        """(value, error estimate) of one lobe: nested adaptive quadrature, w1's polar angle
        outside (split at the support edges and the peaks), its azimuth inside (split at the
        planes of wi and wo and at the peaks)."""
        lo = 0.5 * math.pi if transmitted else 0.0
        peaks = self.peaks(transmitted)
        panels = np.linspace(lo, math.pi, POLAR_PANELS + 1)[1:-1].tolist()
        polar = sorted({t for t in self._polar_breaks(transmitted) + [p[0] for p in peaks]
                        + panels if lo < t < math.pi})
        phi_o = math.atan2(self.wo[1], self.wo[0]) % (2.0 * math.pi)
        panels = np.linspace(0.0, 2.0 * math.pi, AZIMUTH_PANELS + 1)[1:-1].tolist()
        azimuth = sorted({p % (2.0 * math.pi) for p in [math.pi, phi_o, phi_o + math.pi]
                          + [p[1] for p in peaks] + panels} - {0.0})

        def ring(t):
            return integrate.quad(lambda p: self.integrand(transmitted, t, p), 0.0,
                                  2.0 * math.pi, points=azimuth, epsabs=0.0,
                                  epsrel=0.1 * EPSREL, limit=LIMIT)[0]

        value, error = integrate.quad(ring, lo, math.pi, points=polar, epsabs=0.0,
                                      epsrel=EPSREL, limit=LIMIT)
        return value, error

    def value(self) -> tuple[float, float]:
        """(order 2 of f |cos o|, error estimate): both lobes of the first event."""
        parts = [self.lobe(t) for t in (False, True)]
        return sum(p[0] for p in parts), sum(p[1] for p in parts)
