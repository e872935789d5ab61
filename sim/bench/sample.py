"""The sample on the bench: a rough interface on a hemisphere or a slab of the same glass, or an
opaque conductor; the power reaching the detector per unit incident power and solid angle.

`Sample.integrand(wi, wo)` is the radiometric integrand of the aperture integral,
T_in * T_out * (eta_i / eta_o)^2 * f(wi, wo) * |cos o| (power BSDF times the faces the light
crosses), and evaluates each lobe only at the directions that lie on its side.
`Sample.lobe_scales` estimates how fast that integrand varies, to choose quadrature orders.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from sim.bench import optics

KINDS = ("hemisphere", "slab", "conductor")
LIT_FROM = ("air", "hemisphere")
DISTRIBUTIONS = ("beckmann", "ggx", "phong")
MASKINGS = ("separable", "correlated")


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
        self.t_normal = optics.normal_transmittance(spec.eta) if spec.kind != "conductor" else 1.0
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

    @cached_property
    def _transmission_factor(self) -> float:
        """T_in T_out (eta_i / eta_o)^2 for the transmitted lobe through the hemisphere."""
        n, t = self.spec.eta, self.t_normal
        return t / n**2 if self.spec.lit_from == "air" else t * n**2

    def _eval(self, lobe: str, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        self.evaluations[lobe] += len(wi)
        return np.asarray(self.model(lobe).eval(wi, wo), dtype=np.float64)

    def integrand(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """Detector power per incident power per sr at (wi, wo) (..., 3) -> (...)."""
        wi, wo = np.broadcast_arrays(wi, wo)
        out = np.zeros(wi.shape[:-1])
        lit_side = wi[..., 2] > 0
        seen = wo[..., 2] != 0
        refl = seen & ((wo[..., 2] > 0) == lit_side)
        if refl.any():
            t_faces = self.t_normal**2 if self.flipped else 1.0
            out[refl] = t_faces * self._eval("reflection", wi[refl], wo[refl]) * np.abs(
                wo[refl][:, 2])
        trans = seen & ~refl
        if trans.any() and self.spec.kind != "conductor":
            out[trans] = self._transmitted(wi[trans], wo[trans])
        return out

    def _transmitted(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        cos_o = np.abs(wo[:, 2])
        if self.spec.kind == "hemisphere":
            return self._transmission_factor * self._eval("transmission", wi, wo) * cos_o
        # slab: refract back through the polished back face to the direction inside the glass
        n = self.spec.eta
        w_glass = optics.air_to_glass_direction(wo, n)
        t_back = 1.0 - optics.fresnel_dielectric(w_glass[:, 2], 1.0 / n)
        # power into the glass f_t cos_g d omega_g (sim.bsdf's f_t integrates to 1 - F), and
        # cos_g d omega_g = cos_o d omega_o / n^2 across the flat back face
        return self._eval("transmission", wi, w_glass) * t_back * cos_o / n**2

    def lobe_scales(self, wi: np.ndarray, wo: np.ndarray) -> tuple[float, float]:
        """Angular scales (rad) over which the integrand varies near (wi, wo), in wi and in wo:
        the distribution's local width at the coupling half vector, carried to wi and wo by the
        least stretch of the half-vector maps, and capped by the distance to the horizon."""
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
        if wi[2] * w_eval[2] < 0 and eta_i != eta_o:  # refraction: (1 - F) has a TIR edge
            w_h = min(w_h, _tir_distance(wi, h, eta_i, eta_o))
        stretch_o = optics.min_stretch(wi, w_eval, eta_i, eta_o)
        stretch_i = optics.min_stretch(w_eval, wi, eta_o, eta_i)
        scale_o = min(w_h * stretch_o * stretch, _angle_to_horizon(wo))
        scale_i = min(w_h * stretch_i, _angle_to_horizon(wi))
        return max(float(scale_i), 1e-9), max(float(scale_o), 1e-9)
