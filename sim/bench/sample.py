"""The sample on the bench: a rough interface on a hemisphere or a slab of the same glass, or an
opaque conductor; the power reaching the detector per unit incident power and solid angle.

`Sample.integrand(wi, wo)` is the radiometric integrand of the aperture integral,
T_in * T_out * (eta_i / eta_o)^2 * f(wi, wo) * |cos o| (power BSDF times the faces the light
crosses), and evaluates each lobe only at the directions that lie on its side.
`Sample.lobe_scales` estimates how fast that integrand varies, to choose quadrature orders.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from sim.bench import optics

KINDS = ("hemisphere", "slab", "conductor")
LIT_FROM = ("air", "hemisphere")
DISTRIBUTIONS = ("beckmann", "ggx", "phong")
MASKINGS = ("separable", "correlated")


class LobeScales(NamedTuple):
    """Angular scales (rad) near (wi, wo): the smooth lobe's local width in wi and wo, and the
    distance to the nearest edge (a kink: the horizon, masking's cut-off, TIR) in wi and wo."""

    width_i: float
    width_o: float
    edge_i: float
    edge_o: float


@dataclass(frozen=True)
class SampleSpec:
    """What the sample is. eta: glass index, or the conductor's real index with k its
    extinction; alpha: (alpha_x, alpha_y); lit_from "hemisphere" lights the rough face through
    the hemisphere (from the glass side)."""

    kind: str = "hemisphere"
    distribution: str = "ggx"
    alpha: tuple[float, float] = (0.394, 0.394)
    eta: float = 1.51
    k: float = 0.0
    masking: str = "separable"
    lit_from: str = "air"


def exit_view(spec: SampleSpec, wi: np.ndarray, wo: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(w_eval, factor) with detector power per incident power per sr = factor * f(wi, w_eval)
    * |cos o|, for sample-frame wi, wo (..., 3); what the bench integrates and reduce divides by.

    Reflection: 1 (T_normal^2 when lit through the hemisphere). Transmission through the
    hemisphere: T, the curved face's normal-incidence transmittance, either way round (rays
    from the centre cross it unbent, so the aperture's cone and the power in it are kept; f_t
    of Walter's eq. 21 integrates to the transmitted flux fraction, so no n^2: see
    docs/architecture.md, departures). Through a slab: f at the direction inside the glass
    that leaves the polished back face along wo, times that face's transmittance / n^2 (the
    back face widens the cone by n^2). A conductor: 0.
    """
    wi, wo = np.broadcast_arrays(wi, wo)
    reflected = (wo[..., 2] > 0) == (wi[..., 2] > 0)
    n = spec.eta
    t = optics.normal_transmittance(n)
    w_eval = wo
    if spec.kind == "conductor":
        transmitted = np.zeros(wo.shape[:-1])
    elif spec.kind == "hemisphere":
        transmitted = np.full(wo.shape[:-1], t)
    else:
        w_glass = optics.air_to_glass_direction(wo, n)
        w_eval = np.where(reflected[..., None], wo, w_glass)
        transmitted = (1.0 - optics.fresnel_dielectric(w_glass[..., 2], 1.0 / n)) / n**2
    reflected_factor = t**2 if spec.lit_from == "hemisphere" else 1.0
    factor = np.where(reflected, reflected_factor, transmitted)
    return w_eval, np.where(wo[..., 2] == 0, 0.0, factor)


def _slope_scale(distribution: str, alpha: float, t: np.ndarray) -> np.ndarray:
    """Local length scale, in slope space, over which D changes by order one at slope t."""
    if distribution == "ggx":  # D ~ (alpha^2 + t^2)^-2: alpha / 2 at the peak, t / 4 in the tail
        return (alpha**2 + t**2) / (4.0 * t + 2.0 * alpha)
    # Beckmann (and Phong, its close cousin): exp(-t^2 / alpha^2)
    return 0.5 * alpha**2 / (alpha / np.sqrt(2.0) + t)


def _tir_distance(w: np.ndarray, h: np.ndarray, eta_w: float, eta_other: float) -> float:
    """Angle (rad) by which h would have to tilt for light along w to meet total internal
    reflection on it (inf when w is on the rarer side): near that edge 1 - F changes fast."""
    if eta_w <= eta_other:
        return np.inf
    critical = np.arcsin(eta_other / eta_w)
    return float(abs(np.arccos(min(1.0, abs(float(w @ h)))) - critical))


def _angle_to_horizon(w: np.ndarray) -> np.ndarray:
    return np.abs(np.arcsin(np.clip(w[..., 2], -1.0, 1.0)))


class Sample:
    """A sample and the BSDF models of its lobes (each built on first use, one lobe each)."""

    def __init__(self, spec: SampleSpec):
        self.spec = spec
        self.flipped = spec.lit_from == "hemisphere"
        self.n_interior = spec.eta if spec.kind != "conductor" else 1.0
        self._models: dict[str, object] = {}
        self.evaluations = {"reflection": 0, "transmission": 0}

    def model(self, lobe: str):
        """The sim.bsdf model that computes one lobe ("reflection" or "transmission") only."""
        if lobe not in self._models:
            from sim.bsdf import RoughConductor, RoughDielectric

            s = self.spec
            alpha = s.alpha if s.alpha[0] != s.alpha[1] else s.alpha[0]
            if s.kind == "conductor":
                self._models[lobe] = RoughConductor(
                    distribution=s.distribution, alpha=alpha, eta_complex=complex(s.eta, s.k),
                    masking=s.masking)
            else:
                self._models[lobe] = RoughDielectric(
                    distribution=s.distribution, alpha=alpha, eta=s.eta, masking=s.masking,
                    lobes=(lobe,))
        return self._models[lobe]

    def _eval(self, lobe: str, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        self.evaluations[lobe] += len(wi)
        return np.asarray(self.model(lobe).eval(wi, wo), dtype=np.float64)

    def integrand(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """Detector power per incident power per sr at (wi, wo) (..., 3) -> (...)."""
        wi, wo = np.broadcast_arrays(wi, wo)
        w_eval, factor = exit_view(self.spec, wi, wo)
        out = np.zeros(wi.shape[:-1])
        reflected = (wo[..., 2] > 0) == (wi[..., 2] > 0)
        for lobe, on_lobe in (("reflection", reflected), ("transmission", ~reflected)):
            use = on_lobe & (factor > 0)
            if use.any():
                f = self._eval(lobe, wi[use], w_eval[use])
                out[use] = factor[use] * f * np.abs(wo[use][:, 2])
        return out

    def peak_direction(self, wi: np.ndarray, reflection: bool) -> np.ndarray | None:
        """Where a lobe's specular peak leaves (as the detector sees it): the mirror direction,
        the refracted one (straight through for a slab), None under total internal reflection
        or for a conductor's transmission."""
        if reflection:
            return wi * np.array([-1.0, -1.0, 1.0])
        if self.spec.kind == "conductor":
            return None
        if self.spec.kind == "slab":
            return -wi
        eta_rel = self.n_interior if wi[2] > 0 else 1.0 / self.n_interior
        xy = -wi[:2] / eta_rel
        z2 = 1.0 - float(xy @ xy)
        return None if z2 <= 0 else np.array([xy[0], xy[1], -np.sign(wi[2]) * np.sqrt(z2)])

    def lobe_scales(self, wi: np.ndarray, wo: np.ndarray) -> LobeScales:
        """How fast the integrand varies near (wi, wo): the distribution's local width at the
        coupling half vector, and the distance to the lobe's edges (the horizon, a facet seen
        edge-on, the TIR edge of 1 - F), carried to wi and wo by the least stretch of the
        half-vector maps."""
        s = self.spec
        eta_i = 1.0 if wi[2] > 0 else self.n_interior
        eta_o = 1.0 if wo[2] > 0 else self.n_interior
        stretch = 1.0
        w_eval = wo
        if s.kind == "slab" and wo[2] < 0:
            w_eval = optics.air_to_glass_direction(wo, s.eta)
            stretch = s.eta * np.sqrt(abs(w_eval[2]) / max(abs(wo[2]), 1e-300))
        h = optics.half_vector(wi, w_eval, eta_i, eta_o)
        t = np.hypot(h[0], h[1]) / max(h[2], 1e-300)
        w_h = _slope_scale(s.distribution, min(s.alpha), t) * h[2] ** 2
        # edges: a facet seen edge-on from wi or wo; facets standing vertical (h_z = 0), where
        # D stops (GGX's D does not vanish there)
        edge_h = min(abs(float(wi @ h)), abs(float(w_eval @ h)),
                     float(np.arcsin(min(1.0, h[2]))))
        if wi[2] * w_eval[2] < 0 and eta_i != eta_o:
            edge_h = min(edge_h, _tir_distance(wi, h, eta_i, eta_o))
        stretch_o = optics.min_stretch(wi, w_eval, eta_i, eta_o) * stretch
        stretch_i = optics.min_stretch(w_eval, wi, eta_o, eta_i)
        edge_o = min(edge_h * stretch_o, _angle_to_horizon(wo))
        edge_i = min(edge_h * stretch_i, _angle_to_horizon(wi))
        return LobeScales(max(float(w_h * stretch_i), 1e-9), max(float(w_h * stretch_o), 1e-9),
                          float(edge_i), float(edge_o))
