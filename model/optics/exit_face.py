"""What the detector sees of a sample's BSDF: the direction the BSDF is evaluated at and the
faces' transmittance on the way out (hemisphere, slab or an opaque reflector); the bench
integrates it and reduction divides by it."""

from __future__ import annotations

from typing import Protocol

import numpy as np

from model.optics import smooth as optics

#: Kinds of sample that only reflect: a conductor, a diffuse or coated panel, a reflectance
#: standard (gonio.sample.OPAQUE_KINDS names the same).
OPAQUE_KINDS = ("conductor", "diffuse", "coated", "reference")


class SampleFaces(Protocol):
    """The sample's faces as exit_view needs them: its kind ("hemisphere", "slab", or one of
    OPAQUE_KINDS), glass index (None: an opaque sample without one) and the side it is lit
    from ("air" or "hemisphere")."""

    kind: str
    eta: float | None
    lit_from: str


def exit_view(spec: SampleFaces, wi: np.ndarray, wo: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(w_eval, factor) with detector power per incident power per sr = factor * f(wi, w_eval)
    * |cos o|, for sample-frame wi, wo (..., 3); what the bench integrates and reduce divides by.

    Reflection: 1 (T_normal^2 when lit through the hemisphere). Transmission through the
    hemisphere: T, the curved face's normal-incidence transmittance, either way round (rays
    from the centre cross it unbent, so the aperture's cone and the power in it are kept; f_t
    of Walter's eq. 21 integrates to the transmitted flux fraction, so no n^2: see
    docs/architecture.md, departures). Through a slab: f at the direction inside the glass
    that leaves the polished back face along wo, times that face's transmittance / n^2 (the
    back face widens the cone by n^2). An opaque reflector (OPAQUE_KINDS): reflection alone,
    factor 1, transmission 0 (its eta, None for a diffuse or reference panel, is not read).
    """
    wi, wo = np.asarray(wi), np.asarray(wo)
    if wi.shape != wo.shape:
        wi, wo = np.broadcast_arrays(wi, wo)
    reflected = (wo[..., 2] > 0) == (wi[..., 2] > 0)
    if spec.kind in OPAQUE_KINDS:  # no index needed: nothing crosses a face
        return wo, np.where(reflected & (wo[..., 2] != 0), 1.0, 0.0)
    n = spec.eta
    t = optics.normal_transmittance(n)
    w_eval = wo
    if spec.kind == "hemisphere":
        transmitted = np.full(wo.shape[:-1], t)
    else:
        w_glass = optics.air_to_glass_direction(wo, n)
        w_eval = np.where(reflected[..., None], wo, w_glass)
        transmitted = (1.0 - optics.fresnel_dielectric(w_glass[..., 2], 1.0 / n)) / n**2
    reflected_factor = t**2 if spec.lit_from == "hemisphere" else 1.0
    factor = np.where(reflected, reflected_factor, transmitted)
    return w_eval, np.where(wo[..., 2] == 0, 0.0, factor)
