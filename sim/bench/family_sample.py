"""An opaque sample of a model family beside the microfacet interface (model.bsdf.families: a
matte paint, a coated panel, a reflectance standard, an ABg scatterer) on the bench: the
detector's power from the family's eval through the same aperture integral as the microfacet
samples, with the family's own lobe scales choosing the quadrature orders."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from model.bsdf.families import make_family
from model.optics.aperture import LobeScales
from sim.bench.sample import Sample, SampleSpec

#: Width (rad) of the cosine factor's variation: |cos o|'' / |cos o| = -1, so a cap's
#: one-point rule errs by about (half-angle)^2 / 4 on a constant BSDF.
COSINE_WIDTH = 1.0
#: Share of the angle to the horizon over which Oren-Nayar's tan(min(theta_i, theta_o)) term
#: changes by order one (d log tan b / db = 1 / (sin b cos b) <= 2 / b for b <= pi/4).
OREN_NAYAR_SHARE = 0.5
#: ABg beyond its knee falls like |x|^-g: log f changes by one over |x| / g; at the knee the
#: scale is the knee itself. Half of that, as GGX's slope_scale takes a quarter of its tail.
ABG_SHARE = 0.5

Widths = Callable[["FamilySample", np.ndarray, np.ndarray], tuple[float, float]]


def _angle_to_horizon(w: np.ndarray) -> float:
    return abs(math.asin(min(1.0, max(-1.0, float(w[2])))))


def _constant(sample: FamilySample, wi: np.ndarray, wo: np.ndarray) -> tuple[float, float]:
    """Lambert: f is constant, only the cosine factor varies."""
    return COSINE_WIDTH, COSINE_WIDTH


def _oren_nayar(sample: FamilySample, wi: np.ndarray, wo: np.ndarray) -> tuple[float, float]:
    """Oren-Nayar: smooth in both directions on the scale of the nearer one's angle to the
    horizon (its tan terms), within the cosine's."""
    width = OREN_NAYAR_SHARE * min(_angle_to_horizon(wi), _angle_to_horizon(wo))
    return max(min(width, COSINE_WIDTH), 1e-9), max(min(width, COSINE_WIDTH), 1e-9)


def _coat(sample: FamilySample, wi: np.ndarray, wo: np.ndarray) -> tuple[float, float]:
    """A coated base: the coat's microfacet lobe (its distribution at the half vector, as for a
    conductor's reflection), narrower than the base's variation everywhere."""
    scales = Sample.lobe_scales(sample, wi, wo)
    return min(scales.width_i, COSINE_WIDTH), min(scales.width_o, COSINE_WIDTH)


def _abg(sample: FamilySample, wi: np.ndarray, wo: np.ndarray) -> tuple[float, float]:
    """ABg, in the plane of beta at |x| = |wo_xy + wi_xy| from the peak: for g > 0 the knee
    B^(1/g) plus |x|, over g; for g < 0 (f ~ |x|^-g up to the knee, flat beyond) the lesser
    of the two, over -g. An angle moves beta by at most as much, so it is a width in wi and
    wo alike."""
    model = sample.family
    if model.g == 0.0:
        return COSINE_WIDTH, COSINE_WIDTH
    x = float(np.hypot(wo[0] + wi[0], wo[1] + wi[1]))
    knee = math.exp(min(math.log(model.B) / model.g, 0.0))
    reach = knee + x if model.g > 0 else min(knee, x)
    width = max(min(ABG_SHARE * reach / abs(model.g), COSINE_WIDTH), 1e-9)
    return width, width


#: Family name -> how fast its integrand varies (width_i, width_o in rad) at a pair: the
#: families the bench emulates ([sim.sample] family), each with the scale its quadrature needs.
LOBE_WIDTHS: dict[str, Widths] = {
    "lambert": _constant,
    "oren-nayar": _oren_nayar,
    "lambert+microfacet": _coat,
    "abg": _abg,
}
#: Families with a specular lobe: the bench looks for its peak at the mirror direction.
PEAKED = ("lambert+microfacet", "abg")


class FamilySample(Sample):
    """A reflection-only sample whose BSDF is a family's model (spec.family, built with
    make_family from spec.family_parameters and spec.family_settings): no transmission, no
    multiple scattering or diffraction beyond what the family models, the horizon its only
    edge."""

    def __init__(self, spec: SampleSpec, wavelength_nm: float = 632.8,
                 visible_fraction: float = 1e-3, seed: int = 0):
        super().__init__(spec, wavelength_nm, visible_fraction, seed)
        self.family = make_family(spec.family, dict(spec.family_parameters),
                                  **dict(spec.family_settings))
        self.widths = LOBE_WIDTHS[spec.family]

    def model(self, lobe: str = "reflection", masking: str | None = None):
        """The family's model (it has the reflection lobe only)."""
        return self.family

    def multiple_scattering_on(self, theta_i: float) -> bool:
        """Never: a family models its own scattering."""
        return False

    def diffraction_on(self, theta_i: float, lobe: str = "reflection") -> bool:
        """Never: a family models its own scattering."""
        return False

    @property
    def tabulated(self) -> bool:
        """No multiple-scattering tables."""
        return False

    def _eval(self, lobe: str, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        self.evaluations[lobe] += len(wi)
        if lobe == "transmission":
            return np.zeros(len(wi))
        return np.asarray(self.family.eval(wi, wo), dtype=np.float64)

    def peak_direction(self, wi: np.ndarray, reflection: bool) -> np.ndarray | None:
        """The mirror direction for a family with a specular lobe, else None."""
        if reflection and self.spec.family in PEAKED:
            return wi * np.array([-1.0, -1.0, 1.0])
        return None

    def lobe_scales(self, wi: np.ndarray, wo: np.ndarray) -> LobeScales:
        """The family's widths (LOBE_WIDTHS) and the angles to the horizon, its one edge."""
        width_i, width_o = self.widths(self, wi, wo)
        edges = self.edge_circles(wi)
        return LobeScales(width_i, width_o, edges.distance(wi, wo),
                          edges.distance(wo, wi, free_is_wo=False), edges)
