"""The sample on the bench: a rough interface on a hemisphere or a slab of the same glass, or an
opaque conductor; the power reaching the detector per unit incident power and solid angle.
(An opaque sample of another model family is sim.bench.family_sample's FamilySample.)

`Sample.integrand(wi, wo)` is the radiometric integrand of the aperture integral,
T_in * T_out * (eta_i / eta_o)^2 * f(wi, wo) * |cos o| (power BSDF times the faces the light
crosses), and evaluates each lobe only at the directions that lie on its side.
`Sample.lobe_scales` estimates how fast that integrand varies, to choose quadrature orders.
Multiple scattering (orders >= 2 of the Heitz 2016 random walk, tabulated per incidence by
model.bsdf.multiple_scattering.HigherOrderLobe) and diffraction (Holzschuch-Pacanowski 2017,
reflection) are added where the spec asks for them, or with "auto" (the default) only where
their share of the light exceeds `visible_fraction` (the detector's noise floor).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from model.bsdf.distributions import DISTRIBUTIONS
from model.optics import smooth as optics
from model.optics.aperture import LobeScales
from model.optics.edges import EdgeCircles
from model.optics.exit_face import OPAQUE_KINDS, exit_view

KINDS = ("hemisphere", "slab", *OPAQUE_KINDS)
#: The model of a rough interface (this module's Sample), as fit results name it.
MICROFACET = "microfacet"
LIT_FROM = ("air", "hemisphere")
#: Walks per pair of the per-pair random walk used for anisotropic samples, per table walk
#: (a pair's walk costs about what scoring 16 table directions does).
ANISOTROPIC_WALK_SHARE = 16
#: Points of the diffraction lobe integral per direction pair (TwoScaleDiffraction samples).
DIFFRACTION_SAMPLES = 256


@dataclass(frozen=True)
class SampleSpec:
    """What the sample is. eta: glass index, or the conductor's real index with k its
    extinction; alpha: (alpha_x, alpha_y); lit_from "hemisphere" lights the rough face through
    the hemisphere (from the glass side). family: the model, MICROFACET (the rough interface)
    or a name of model.bsdf.families.FAMILIES, whose parameters and fixed settings by name
    family_parameters and family_settings give (a coat's distribution, alpha, eta and masking
    are also the fields above)."""

    kind: str = "hemisphere"
    distribution: str = "ggx"
    alpha: tuple[float, float] = (0.394, 0.394)
    eta: float = 1.51
    k: float = 0.0
    masking: str = "separable"
    lit_from: str = "air"
    multiple_scattering: bool | str = "auto"  # True | False | "auto"
    diffraction: bool | str = "auto"  # True | False | "auto"
    rms_height_nm: float | None = None  # nano-roughness (K-correlation PSD) for diffraction
    correlation_length_um: float | None = None
    psd_exponent: float = 2.0
    ms_walks: int = 1 << 16  # random walks per incidence table of the multiple-scattering term
    family: str = MICROFACET
    family_parameters: tuple[tuple[str, float], ...] = ()
    family_settings: tuple[tuple[str, str], ...] = ()


def _tir_distance(w: np.ndarray, h: np.ndarray, eta_w: float, eta_other: float) -> float:
    """Angle (rad) by which h would have to tilt for light along w to meet total internal
    reflection on it (inf when w is on the rarer side): near that edge 1 - F changes fast."""
    if eta_w <= eta_other:
        return np.inf
    critical = np.arcsin(eta_other / eta_w)
    return float(abs(np.arccos(min(1.0, abs(float(w @ h)))) - critical))


def _angle_to_horizon(w: np.ndarray) -> np.ndarray:
    return np.abs(np.arcsin(np.clip(w[..., 2], -1.0, 1.0)))


class HigherOrders:
    """Scattering orders >= 2 of the random walk on a model's microsurface (Heitz 2016): what a
    single-scattering model leaves out, to add to it. Each chunk of pairs is walked twice from
    the same seed, all orders and order 1 alone, so order 1 (and its noise) cancels exactly.

    correlated: the model with height-correlated masking (the walk's own order 1); walks: walks
    per pair; seed: fixed_seed=True uses the same random numbers at every call (a deterministic
    objective for fits), otherwise each call draws fresh ones from (seed, call number).
    """

    def __init__(self, correlated, walks: int, seed: int, fixed_seed: bool = False):
        from model.bsdf.multiple_scattering import RandomWalkBSDF
        from model.bsdf.multiple_scattering.model import BATCH

        if not 1 <= walks <= BATCH:
            raise ValueError(f"walks must be in [1, {BATCH}] (one batch per pair), got {walks!r}")
        self.walk = RandomWalkBSDF(correlated, walks=walks)
        self.seed, self.fixed_seed, self.calls = int(seed), fixed_seed, 0

    def eval(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """Orders >= 2 of f(wi, wo) in 1/sr, no cosine; wi, wo (..., 3) broadcast."""
        from model.bsdf.multiple_scattering.model import BATCH

        wi, wo = np.broadcast_arrays(np.asarray(wi, np.float64), np.asarray(wo, np.float64))
        shape = wi.shape[:-1]
        wi, wo = wi.reshape(-1, 3), wo.reshape(-1, 3)
        key = [self.seed] if self.fixed_seed else [self.seed, self.calls]
        self.calls += 1
        chunk = max(1, BATCH // self.walk.walks)
        starts = range(0, len(wi), chunk)
        seeds = np.random.SeedSequence(key).spawn(len(starts))
        out = np.empty(len(wi))
        for start, seq in zip(starts, seeds, strict=True):
            part = slice(start, start + chunk)
            every = self.walk.eval(wi[part], wo[part], np.random.default_rng(seq))
            first = self.walk.eval(wi[part], wo[part], np.random.default_rng(seq), order=1)
            out[part] = every - first
        return out.reshape(shape)


@lru_cache(maxsize=64)
def higher_order_lobe(kind: str, distribution: str, alpha: float, eta: float, k: float,
                      walks: int, seed: int):
    """The HigherOrderLobe of a sample's microsurface (height-correlated masking), shared by
    every bench of the process with the same parameters and kept on disk (plane_store), so
    its tables are walked once per machine."""
    from model.bsdf import RoughConductor, RoughDielectric
    from model.bsdf.multiple_scattering import HigherOrderLobe

    if kind == "conductor":
        parent = RoughConductor(distribution=distribution, alpha=alpha,
                                eta_complex=complex(eta, k), masking="correlated")
    else:
        parent = RoughDielectric(distribution=distribution, alpha=alpha, eta=eta,
                                 masking="correlated")
    return HigherOrderLobe(parent, walks=walks, seed=seed, cache_as={
        "kind": kind, "distribution": distribution, "alpha": alpha, "eta": eta, "k": k,
        "masking": "correlated"})


@lru_cache(maxsize=4096)
def _lost_energy(distribution: str, alpha: tuple[float, float], eta: float | complex,
                 theta: float) -> float:
    from model.bsdf.multiple_scattering import energy_loss

    return energy_loss(distribution, alpha if alpha[0] != alpha[1] else alpha[0], eta, theta,
                       masking="correlated")


class Sample:
    """A sample and the BSDF models of its lobes (each built on first use, one lobe each).

    wavelength_nm: the source's; visible_fraction: share of the incident power, spread over
    the hemisphere, below which an "auto" effect is not computed (the detector's noise floor
    over Phi (aperture radius / distance)^2); seed: the random walks' seed, fixed for the
    sample's life so the bench stays a deterministic function of the stage positions.
    """

    def __init__(self, spec: SampleSpec, wavelength_nm: float = 632.8,
                 visible_fraction: float = 1e-3, seed: int = 0):
        self.spec = spec
        self.flipped = spec.lit_from == "hemisphere"
        self.n_interior = spec.eta if spec.kind not in OPAQUE_KINDS else 1.0
        self.wavelength_m = wavelength_nm * 1e-9
        self.visible_fraction = visible_fraction
        self.seed = seed
        self._models: dict[tuple, object] = {}
        self.evaluations = {"reflection": 0, "transmission": 0, "random_walk": 0,
                            "diffraction": 0}
        #: while collecting (tabulated_planes): the table planes evaluations missed, by lobe
        self._missed: dict[object, set] | None = None

    def model(self, lobe: str, masking: str | None = None):
        """The single-scattering model.bsdf model of one lobe ("reflection" or "transmission")
        only, with the spec's masking unless another is named."""
        key = (lobe, masking or self.spec.masking)
        if key not in self._models:
            from model.bsdf import RoughConductor, RoughDielectric

            s = self.spec
            alpha = s.alpha if s.alpha[0] != s.alpha[1] else s.alpha[0]
            if s.kind == "conductor":
                self._models[key] = RoughConductor(
                    distribution=s.distribution, alpha=alpha, eta_complex=complex(s.eta, s.k),
                    masking=key[1])
            else:
                self._models[key] = RoughDielectric(
                    distribution=s.distribution, alpha=alpha, eta=s.eta, masking=key[1],
                    lobes=(lobe,))
        return self._models[key]

    def _extra(self, name: str, lobe: str):
        """The lobe's multiple-scattering (HigherOrders) or diffraction model, built once."""
        key = (name, lobe)
        if key not in self._models:
            s = self.spec
            if name == "random_walk" and s.alpha[0] == s.alpha[1]:
                self._models[key] = higher_order_lobe(s.kind, s.distribution, s.alpha[0], s.eta,
                                                      s.k, s.ms_walks, self.seed)
            elif name == "random_walk":
                from model.bsdf.multiple_scattering.model import BATCH

                walks = min(BATCH, max(2, s.ms_walks // ANISOTROPIC_WALK_SHARE))
                self._models[key] = HigherOrders(self.model(lobe, "correlated"), walks,
                                                 self.seed, fixed_seed=True)
            else:
                from model.bsdf.diffraction import KCorrelationPSD, TwoScaleDiffraction

                psd = KCorrelationPSD(s.rms_height_nm * 1e-9, s.correlation_length_um * 1e-6,
                                      s.psd_exponent)
                self._models[key] = TwoScaleDiffraction(self.model(lobe), psd,
                                                        DIFFRACTION_SAMPLES)
        return self._models[key]

    def multiple_scattering_on(self, theta_i: float) -> bool:
        """Whether orders >= 2 are added at incidence theta_i (rad from the normal): the spec's
        switch, or with "auto" the energy single scattering loses (energy_loss, correlated
        masking) above visible_fraction."""
        s = self.spec
        if s.multiple_scattering != "auto":
            return bool(s.multiple_scattering)
        if not DISTRIBUTIONS[s.distribution].multiple_scattering or theta_i >= 0.5 * np.pi:
            return False
        eta = complex(s.eta, s.k) if s.kind == "conductor" else (
            1.0 / s.eta if self.flipped else s.eta)
        loss = _lost_energy(s.distribution, s.alpha, eta, round(float(theta_i), 4))
        return loss > self.visible_fraction

    def diffraction_on(self, theta_i: float, lobe: str = "reflection") -> bool:
        """Whether the lobe ("reflection" or "transmission") is the two-scale diffraction model
        at incidence theta_i: the spec's switch, or with "auto" when the Harvey-Shack diffracted
        share 1 - A (transmitted: phase path eta cos theta_t - cos theta_i) exceeds
        visible_fraction while the specular share A does too (a surface far rougher than the
        wavelength scatters by geometric optics alone, which the microfacet model is)."""
        s = self.spec
        if s.diffraction != "auto":
            return bool(s.diffraction)
        if s.rms_height_nm is None or self.flipped:
            return False
        from model.bsdf.diffraction import diffraction_fraction

        eta = s.eta if lobe == "transmission" else None
        moved = diffraction_fraction(s.rms_height_nm * 1e-9, self.wavelength_m, theta_i, eta)
        return self.visible_fraction < moved < 1.0 - self.visible_fraction

    def _eval(self, lobe: str, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        self.evaluations[lobe] += len(wi)
        theta_i = math.acos(min(1.0, abs(float(np.add.reduce(wi[:, 2])) / len(wi))))  # the mean's
        if self.diffraction_on(theta_i, lobe):
            self.evaluations["diffraction"] += len(wi)
            f = self._extra("diffraction", lobe).eval(wi, wo, self.wavelength_m)
        else:
            f = np.asarray(self.model(lobe).eval(wi, wo), dtype=np.float64)
        if self.multiple_scattering_on(theta_i):
            f = f + self._higher_orders(lobe, wi, wo)
        return f

    def _higher_orders(self, lobe: str, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """Orders >= 2 at each pair: interpolated from the lobe's tables (isotropic), or
        walked per pair (anisotropic)."""
        self.evaluations["random_walk"] += len(wi)
        model = self._extra("random_walk", lobe)
        if self._missed is None:
            return model.eval(wi, wo)
        return model.eval(wi, wo, missing=self._missed.setdefault(model, set()))

    @property
    def tabulated(self) -> bool:
        """Whether orders >= 2 can come from tables (HigherOrderLobe): switched on or "auto",
        on an isotropic microsurface."""
        s = self.spec
        return s.multiple_scattering is not False and s.alpha[0] == s.alpha[1]

    def table_lobes(self) -> list:
        """The HigherOrderLobes (tables) the sample has made so far, each once."""
        from model.bsdf.multiple_scattering import HigherOrderLobe

        lobes = [m for m in self._models.values() if isinstance(m, HigherOrderLobe)]
        return list({id(lobe): lobe for lobe in lobes}.values())

    @contextmanager
    def collecting(self) -> Iterator[dict[object, set]]:
        """Within the block, evaluations build no table plane: each lobe's missing planes
        (HigherOrderLobe.build_at's addresses) are added to the dict it yields, by lobe, and
        their share is left out of the values (so an evaluation's value is a lower bound)."""
        missed: dict[object, set] = {}
        self._missed = missed
        try:
            yield missed
        finally:
            self._missed = None

    def bsdf(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """The BSDF the bench uses at sample-frame pairs (..., 3), with the multiple scattering
        and diffraction it switches on (for plots of a run's generating model)."""
        wi, wo = np.broadcast_arrays(wi, wo)
        flat_i, flat_o = wi.reshape(-1, 3), wo.reshape(-1, 3)
        out = np.zeros(len(flat_i))
        reflected = (flat_o[:, 2] > 0) == (flat_i[:, 2] > 0)
        for lobe, on_lobe in (("reflection", reflected), ("transmission", ~reflected)):
            if on_lobe.any():
                out[on_lobe] = self._eval(lobe, flat_i[on_lobe], flat_o[on_lobe])
        return out.reshape(wi.shape[:-1])

    def integrand(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """Detector power per incident power per sr at (wi, wo) (..., 3) -> (...)."""
        wi, wo = np.broadcast_arrays(wi, wo)
        shape = wi.shape[:-1]
        wi, wo = wi.reshape(-1, 3), wo.reshape(-1, 3)
        w_eval, factor = exit_view(self.spec, wi, wo)
        out = np.zeros(len(wi))
        reflected = (wo[:, 2] > 0) == (wi[:, 2] > 0)
        live = factor > 0
        for lobe, on_lobe in (("reflection", reflected), ("transmission", ~reflected)):
            use = on_lobe & live
            if not use.any():
                continue
            if use.all():  # every pair (a single reading's ray): no gathering and scattering;
                # copies, as gathering made (a broadcast view would reach numba's kernels)
                out = factor * self._eval(lobe, wi.copy(), w_eval.copy()) * np.abs(wo[:, 2])
            else:
                f = self._eval(lobe, wi[use], w_eval[use])
                out[use] = factor[use] * f * np.abs(wo[use, 2])
        return out.reshape(shape)

    def peak_direction(self, wi: np.ndarray, reflection: bool) -> np.ndarray | None:
        """Where a lobe's specular peak leaves (as the detector sees it): the mirror direction,
        the refracted one (straight through for a slab), None under total internal reflection
        or for an opaque sample's transmission."""
        if reflection:
            return wi * np.array([-1.0, -1.0, 1.0])
        if self.spec.kind in OPAQUE_KINDS:
            return None
        if self.spec.kind == "slab":
            return -wi
        eta_rel = self.n_interior if wi[2] > 0 else 1.0 / self.n_interior
        xy = -wi[:2] / eta_rel
        z2 = 1.0 - float(xy @ xy)
        return None if z2 <= 0 else np.array([xy[0], xy[1], -np.sign(wi[2]) * np.sqrt(z2)])

    def lobe_scales(self, wi: np.ndarray, wo: np.ndarray) -> LobeScales:
        """How fast the integrand varies near (wi, wo): the distribution's local width at the
        coupling half vector, carried to wi and wo by the least stretch of the half-vector
        maps, and the angles to the nearest edges (exact, from edge_circles)."""
        s = self.spec
        eta_i = 1.0 if wi[2] > 0 else self.n_interior
        eta_o = 1.0 if wo[2] > 0 else self.n_interior
        stretch = 1.0
        w_eval = wo
        if s.kind == "slab" and wo[2] < 0:
            w_eval = optics.air_to_glass_direction(wo, s.eta)
            stretch = s.eta * np.sqrt(abs(w_eval[2]) / max(abs(wo[2]), 1e-300))
        h = optics.half_vector(wi, w_eval, eta_i, eta_o)
        t = np.hypot(h[0], h[1]) / max(h[2], 1e-9)  # finite on vertical facets (h_z = 0)
        w_h = DISTRIBUTIONS[s.distribution].slope_scale(min(s.alpha), t) * h[2] ** 2
        stretch_o = optics.min_stretch(wi, w_eval, eta_i, eta_o) * stretch
        stretch_i = optics.min_stretch(w_eval, wi, eta_o, eta_i)
        edges = self.edge_circles(wi)
        if edges is not None:
            edge_o, edge_i = edges.distance(wi, wo), edges.distance(wo, wi, free_is_wo=False)
        else:  # a slab: the edges of f at w_eval (inside the glass), carried to wo and wi
            edge_h = min(abs(float(wi @ h)), abs(float(w_eval @ h)),
                         float(np.arcsin(min(1.0, h[2]))))
            if wi[2] * w_eval[2] < 0 and eta_i != eta_o:
                edge_h = min(edge_h, _tir_distance(wi, h, eta_i, eta_o))
            edge_o = min(edge_h * stretch_o, _angle_to_horizon(wo))
            edge_i = min(edge_h * stretch_i, _angle_to_horizon(wi))
        return LobeScales(max(float(w_h * stretch_i), 1e-9), max(float(w_h * stretch_o), 1e-9),
                          float(edge_i), float(edge_o), edges)

    def edge_circles(self, wi: np.ndarray) -> EdgeCircles | None:
        """The integrand's edges as circles at incidence about wi (3,), or None for a slab (its
        transmitted lobe is evaluated inside the glass, where the edges are circles of w_eval,
        not of wo). With tabulated multiple scattering on, its theta_o grid adds kinks."""
        s = self.spec
        if s.kind == "slab":
            return None
        step = None
        theta_i = float(np.arccos(min(1.0, abs(float(wi[2])))))
        if s.alpha[0] == s.alpha[1] and self.multiple_scattering_on(theta_i):
            from model.bsdf.multiple_scattering.lobe import THETA_STEP_DEG as step
        return EdgeCircles(1.0, self.n_interior, s.kind not in OPAQUE_KINDS, step)
