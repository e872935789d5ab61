"""The model a fit evaluates for one parameter set: the microfacet BSDF of model.bsdf, with the
two-scale diffraction term and the random walk's orders >= 2 when the fit asks for them."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

# Points of the two-scale model's lobe integral per pair: the bench's (sim.bench.sample), so a
# fit of an emulated run evaluates the same fixed point set.
DIFFRACTION_SAMPLES = 256


class Diffracted:
    """TwoScaleDiffraction at a fixed wavelength, with the eval(wi, wo) signature of the
    microfacet models (what Smearing.average calls)."""

    def __init__(self, model: Any, settings: Diffraction):
        from model.bsdf.diffraction import KCorrelationPSD, TwoScaleDiffraction

        psd = KCorrelationPSD(settings.rms_height_nm * 1e-9,
                              settings.correlation_length_um * 1e-6, settings.psd_exponent)
        self.two_scale = TwoScaleDiffraction(model, psd, settings.samples)
        self.wavelength_m = settings.wavelength_nm * 1e-9

    def eval(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """f(wi, wo) in 1/sr: specular share of the microfacet lobe plus the diffracted lobe."""
        wi, wo = np.broadcast_arrays(wi, wo)
        return self.two_scale.eval(wi, wo, self.wavelength_m)


@dataclass(frozen=True)
class Diffraction:
    """Held-fixed nano-roughness and wavelength of a fit's two-scale diffraction term."""

    rms_height_nm: float
    correlation_length_um: float
    psd_exponent: float
    wavelength_nm: float
    samples: int = DIFFRACTION_SAMPLES

    def wrap(self, model: Any) -> Diffracted:
        """The two-scale model (model.bsdf.diffraction.TwoScaleDiffraction) around `model`, with
        eval(wi, wo) at this wavelength."""
        return Diffracted(model, self)

    def to_dict(self) -> dict[str, float]:
        """The settings as a JSON-ready dict."""
        return {"rms_height_nm": self.rms_height_nm,
                "correlation_length_um": self.correlation_length_um,
                "psd_exponent": self.psd_exponent, "wavelength_nm": self.wavelength_nm,
                "samples": self.samples}


class _WithHigherOrders:
    """A single-scattering model plus the random walk's orders >= 2 on the same microsurface
    (model.bsdf.multiple_scattering.higher_orders_at: walked forward at the pairs, fixed seed,
    so a pair's value is the same whichever pairs share the call)."""

    def __init__(self, single: Any, correlated: Any, walks: int, seed: int):
        self.single, self.correlated = single, correlated
        self.walks, self.seed = walks, seed

    def eval(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """f(wi, wo) in 1/sr: single scattering plus orders >= 2."""
        from model.bsdf.multiple_scattering import higher_orders_at

        wi, wo = np.broadcast_arrays(wi, wo)
        extra = higher_orders_at(self.correlated, wi, wo, self.walks, self.seed,
                                 covariance=False, both_ways=False)[0]
        return self.single.eval(wi, wo) + extra.reshape(wi.shape[:-1])


def build_model(distribution: str, alpha: float | tuple[float, float], eta: float,
                masking: str, k: float | None = None, walks: int | None = None,
                seed: int = 0, diffraction: Diffraction | None = None) -> Any:
    """The model.bsdf model for one parameter set: a RoughDielectric, or a RoughConductor of
    complex index eta + i k when k is given (imported here so calibration loads without it);
    with diffraction, the two-scale model around it; with walks, plus multiple scattering
    (orders >= 2, `walks` walks per pair, fixed seed), which diffraction leaves alone (the
    nano-roughness spreads an already broad lobe)."""
    from model.bsdf import RoughConductor, RoughDielectric

    if walks is not None:  # orders >= 2 of the microsurface beside the (diffracted) order 1
        return _WithHigherOrders(build_model(distribution, alpha, eta, masking, k,
                                             diffraction=diffraction),
                                 build_model(distribution, alpha, eta, "correlated", k),
                                 walks, seed)
    if diffraction is not None:
        return diffraction.wrap(build_model(distribution, alpha, eta, masking, k))
    if k is not None:
        return RoughConductor(distribution=distribution, alpha=alpha,
                              eta_complex=complex(eta, k), masking=masking)
    return RoughDielectric(distribution=distribution, alpha=alpha, eta=eta, masking=masking)
