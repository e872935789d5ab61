"""Fit microfacet model parameters to reduced BSDF data by weighted least squares.

The model is `model.bsdf.RoughDielectric` (distribution, alpha or (alpha_x, alpha_y), eta,
masking form) times an optional scale factor. Fits run on a chosen subset (by default normal
incidence only, as Walter et al. 2007 did) and the fitted model then predicts the rest, so
the held-out chi-square tests the model rather than the fit. See docs/fitting.md.

The package's parts: options (FitOptions, the diffraction settings, the fitted subset), model
(build_model), orders (the multiple-scattering term), problem (one candidate's least squares),
solve (its solution), result (FitResult), run (fit) and progress (its progress lines); beside
them the other model families: family (one family candidate's least squares), select (the
comparison of the families a sample's kind allows) and pattern (where the residuals lie).
"""

from calibration.fit.model import Diffraction, build_model
from calibration.fit.options import FitError, FitOptions, fit_subset_mask
from calibration.fit.orders import (
    MS_CENTRE_WALKS,
    MS_REWALK_SIGMA,
    MS_REWALK_WALKS,
    refit_orders,
    walked_orders,
)
from calibration.fit.problem import initial_alpha
from calibration.fit.result import FitResult
from calibration.fit.run import fit
from calibration.fit.select import select

__all__ = [
    "MS_CENTRE_WALKS", "MS_REWALK_SIGMA", "MS_REWALK_WALKS", "Diffraction", "FitError",
    "FitOptions", "FitResult", "build_model", "fit", "fit_subset_mask", "initial_alpha",
    "refit_orders", "select", "walked_orders",
]
