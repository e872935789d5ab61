"""The preferred fit as `fit` returns it: parameters with 1-sigma uncertainties, chi-square on the
fitted and held-out points, every candidate's score, and the fitted model's predictions."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from calibration.fit.model import Diffraction, build_model
from calibration.fit.orders import MS_CENTRE_WALKS, walked_orders
from calibration.smearing import Smearing

# A distribution is "preferred" only if it beats the next by this chi-square (2 sigma for one
# extra degree of freedom); otherwise the result says the data cannot tell them apart.
PREFERENCE_DELTA_CHI2 = 4.0



# A fit whose chi2/dof (fitted or held out) exceeds this does not describe the data within
# their uncertainties: exports refuse it, gonio fit and plot warn, reduction notes a slope from it.
MAX_CHI2_DOF = 3.0


def worst_chi2_dof(fitted: float, held_out: float | None) -> tuple[float, str]:
    """(the larger of a fit's fitted and held-out chi2/dof, "fitted" or "held-out"): what
    MAX_CHI2_DOF is held against, by exports and by `gonio fit`'s warning alike."""
    if held_out is not None and held_out > fitted:
        return held_out, "held-out"
    return fitted, "fitted"

@dataclass
class FitResult:
    """The preferred fit: parameters with 1-sigma uncertainties, chi-square per degree of
    freedom on the fitted subset and on the held-out points, and every candidate's score."""

    distribution: str
    masking: str
    names: tuple[str, ...]
    values: np.ndarray
    errors: np.ndarray
    covariance: np.ndarray
    eta: float
    k: float | None  # conductor extinction coefficient, None for a dielectric
    chi2_dof_fit: float
    n_fit: int
    chi2_dof_heldout: float | None
    n_heldout: int
    preferred_by: float | None  # chi-square margin over the runner-up distribution
    candidates: list[dict[str, Any]] = field(default_factory=list)
    optics: Smearing = field(default_factory=lambda: Smearing(0.0, 0, 0.0, 0))
    walks: int | None = None  # walks per incidence of predictions' orders >= 2 (the fitted
    # points' term at the result walked MS_CENTRE_WALKS times as many); None: off
    seed: int = 0
    slope_only: bool = False  # FitOptions.ms_slope_only: the fitted term is the table's (no
    # refit) and predictions walk all pairs forward, each pair's value its own; else
    # transmitted pairs in reverse where better (higher_orders_at's both_ways)
    diffraction: Diffraction | None = None  # the two-scale term the fit used; None: off
    fit_time_s: float = 0.0  # wall time of fit()
    family: str = "microfacet"  # model.bsdf.families' name of the model, or the microfacet one
    settings: dict[str, Any] = field(default_factory=dict)  # a family's fixed settings
    fixed: dict[str, float] = field(default_factory=dict)  # a family's parameters held fixed
    criterion: str | None = None  # the information criterion a family selection ranked by
    residual_pattern: dict[str, Any] | None = None  # calibration.fit.pattern's, of the choice

    @property
    def clearly_preferred(self) -> bool:
        """True when the chosen distribution beats every other by PREFERENCE_DELTA_CHI2."""
        return self.preferred_by is None or self.preferred_by >= PREFERENCE_DELTA_CHI2

    def param(self, name: str) -> tuple[float, float]:
        """(value, 1-sigma uncertainty) of one fitted parameter."""
        k = self.names.index(name)
        return float(self.values[k]), float(self.errors[k])

    @property
    def alpha(self) -> float | tuple[float, float]:
        """Fitted roughness: a number, or (alpha_x, alpha_y) for an anisotropic fit."""
        if "alpha" in self.names:
            return self.param("alpha")[0]
        return self.param("alpha_x")[0], self.param("alpha_y")[0]

    @property
    def scale(self) -> float:
        """Fitted overall scale factor (1 when not fitted)."""
        return self.param("scale")[0] if "scale" in self.names else 1.0

    def model(self) -> Any:
        """The fitted model.bsdf model (without the scale factor), with the multiple-scattering
        term the fit used, if any; a family's model for a family fit."""
        if self.family != "microfacet":
            from model.bsdf.families import make_family

            values = {n: float(v) for n, v in zip(self.names, self.values, strict=True)
                      if n != "scale"}
            return make_family(self.family, {**values, **self.fixed}, **self.settings)
        return build_model(self.distribution, self.alpha, self.eta, self.masking, self.k,
                           self.walks, self.seed, self.diffraction)

    def predict(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """Model BSDF (1/sr) at direction pairs, as the fit compared it with the data
        (scale factor and aperture average of single scattering included; the broad
        multiple-scattering lobe, if any, at the pairs themselves)."""
        return self.predict_with_error(wi, wo)[0]

    def predict_with_error(self, wi: np.ndarray, wo: np.ndarray
                           ) -> tuple[np.ndarray, np.ndarray]:
        """predict() and its standard error: the Monte Carlo error of the walked
        multiple-scattering orders (0 without them), which the fit adds to each point's sigma."""
        if self.family != "microfacet":
            f = self.optics.average(self.model(), wi, wo)
            return self.scale * f, np.zeros_like(f)
        single = build_model(self.distribution, self.alpha, self.eta, self.masking, self.k,
                             diffraction=self.diffraction)
        f = self.optics.average(single, wi, wo)
        err = np.zeros_like(f)
        if self.walks is not None:
            orders, err, _ = walked_orders(self.distribution, self.alpha, self.eta, self.k, wi,
                                           wo, self.walks, self.seed,
                                           both_ways=not self.slope_only)
            f = f + orders
        return self.scale * f, abs(self.scale) * err

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready summary (what `gonio fit --json` prints)."""
        params = {n: {"value": float(v), "sigma": float(e)}
                  for n, v, e in zip(self.names, self.values, self.errors, strict=True)}
        params.update({n: {"value": v, "sigma": 0.0, "fixed": True}
                       for n, v in self.fixed.items()})
        if self.family != "microfacet":
            return self._summary(params)
        if "eta" not in params:
            params["eta"] = {"value": self.eta, "sigma": 0.0, "fixed": True}
        if self.k is not None:
            params["k"] = {"value": self.k, "sigma": 0.0, "fixed": True}
        if self.distribution == "phong":
            a = np.atleast_1d(self.alpha)
            params["phong_exponent"] = {"value": float(2.0 / (a[0] * a[-1]) - 2.0)}
        return self._summary(params)

    def _summary(self, params: dict[str, Any]) -> dict[str, Any]:
        """to_dict's object with the parameters `params` (by name, value and sigma)."""
        return {
            "family": self.family,
            "settings": self.settings,
            "criterion": self.criterion,
            "residual_pattern": self.residual_pattern,
            "distribution": self.distribution,
            "masking": self.masking,
            "parameters": params,
            "chi2_dof_fit": self.chi2_dof_fit,
            "n_fit": self.n_fit,
            "chi2_dof_heldout": self.chi2_dof_heldout,
            "n_heldout": self.n_heldout,
            "preferred_by_delta_chi2": self.preferred_by,
            "clearly_preferred": self.clearly_preferred,
            "aperture_half_angle_deg": self.optics.aperture_deg,
            "beam_divergence_deg": self.optics.divergence_deg,
            "multiple_scattering": (None if self.walks is None
                                    else {"walks": self.walks, "seed": self.seed,
                                          "fitted_walks": self.walks * (1 if self.slope_only
                                                                  else MS_CENTRE_WALKS)}),
            "diffraction": None if self.diffraction is None else self.diffraction.to_dict(),
            "fit_time_s": self.fit_time_s,
            "candidates": self.candidates,
        }
