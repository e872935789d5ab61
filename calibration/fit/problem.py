"""One candidate (distribution, masking) as a least-squares problem: its internal parameters and
their bounds, the model at the data's pairs, the whitened residuals, and where it starts."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from calibration.fit.model import Diffraction, build_model
from calibration.fit.options import (
    ALPHA_BOUNDS,
    ETA_BOUNDS,
    SCALE_BOUNDS,
    FitOptions,
    walk_settings,
)
from calibration.fit.orders import OrdersTable, walked_orders
from calibration.fit.progress import Progress
from calibration.reduced import ReducedData
from calibration.smearing import Smearing

# Alphas about the microfacet model's best start at which a diffraction fit scores its own.
START_REFINE = 5


class Problem:
    """One candidate (distribution, masking) as a least-squares problem in internal parameters:
    log alpha (one or two), eta (if free), log scale (if free)."""

    def __init__(self, data: ReducedData, distribution: str, masking: str, options: FitOptions,
                 eta0: float, k: float | None, optics: Smearing,
                 diffraction: Diffraction | None = None, progress: Progress | None = None):
        self.data, self.distribution, self.masking = data, distribution, masking
        self.diffraction = diffraction
        self.options, self.eta0, self.k = options, eta0, k
        self.optics = optics
        names = ["alpha_x", "alpha_y"] if options.anisotropic else ["alpha"]
        lo = [math.log(ALPHA_BOUNDS[0])] * len(names)
        hi = [math.log(ALPHA_BOUNDS[1])] * len(names)
        if options.fit_eta:
            names.append("eta")
            lo.append(ETA_BOUNDS[0])
            hi.append(ETA_BOUNDS[1])
        if options.fit_scale:
            names.append("scale")
            lo.append(math.log(SCALE_BOUNDS[0]))
            hi.append(math.log(SCALE_BOUNDS[1]))
        self.names, self.lower, self.upper = tuple(names), np.array(lo), np.array(hi)
        self.orders: OrdersTable | None = None
        self.progress = progress if progress is not None else Progress(None)

    @property
    def sigma(self) -> np.ndarray:
        """Each fitted point's 1-sigma as the fit weighs it: the data's, with the
        multiple-scattering table's Monte Carlo error (the model's own) in quadrature."""
        if self.orders is None:
            return self.data.sigma
        return np.hypot(self.data.sigma, self.orders.error)

    def unpack(self, x: np.ndarray) -> tuple[Any, float, float]:
        """(alpha, eta, scale) from internal parameters."""
        k = 2 if self.options.anisotropic else 1
        alpha = (math.exp(x[0]), math.exp(x[1])) if k == 2 else math.exp(x[0])
        eta = float(x[k]) if self.options.fit_eta else self.eta0
        scale = math.exp(x[-1]) if self.options.fit_scale else 1.0
        return alpha, eta, scale

    def external(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Parameter values and d(external)/d(internal) on the diagonal."""
        values, deriv = np.empty(len(x)), np.empty(len(x))
        for k, name in enumerate(self.names):
            log_param = name != "eta"
            values[k] = math.exp(x[k]) if log_param else x[k]
            deriv[k] = values[k] if log_param else 1.0
        return values, deriv

    def predict(self, x: np.ndarray, data: ReducedData) -> np.ndarray:
        """The model at the data's pairs (predict_with_error without its error)."""
        return self.predict_with_error(x, data)[0]

    def predict_with_error(self, x: np.ndarray, data: ReducedData
                           ) -> tuple[np.ndarray, np.ndarray]:
        """The model at the data's pairs and the Monte Carlo standard error (times the scale)
        of its multiple-scattering term: walked at the pairs (higher_orders_at) for points
        outside the fitted subset; 0 on the fitted points (the table's error is in their
        sigma) and without multiple scattering."""
        alpha, eta, scale = self.unpack(x)
        model = build_model(self.distribution, alpha, eta, self.masking, self.k,
                            diffraction=self.diffraction)
        f = self.optics.average(model, data.wi, data.wo)
        err = np.zeros_like(f)
        if self.orders is not None and data is self.data:  # the fit: single + tabulated orders
            f = f + self.orders(alpha)
        elif self.options.multiple_scattering:  # the broad lobe at the points, as the fit has it
            walks, seed = walk_settings(self.options)
            orders, err, _ = walked_orders(self.distribution, alpha, eta, self.k, data.wi,
                                           data.wo, walks, seed)
            f = f + orders
        return scale * f, scale * err

    def residuals(self, x: np.ndarray) -> np.ndarray:
        """The fitted points' whitened residuals at x, weighed by `sigma` (what the optimiser
        minimises; a non-finite one counts as 1e6)."""
        r = self.data.whitened(self.predict(x, self.data), self.sigma)
        r = np.where(np.isfinite(r), r, 1e6)
        self.progress.evaluated(self, r)
        return r

    def start(self, alpha0: float) -> np.ndarray:
        """Best of a coarse log-alpha grid about the peak-width estimate (a guard against a
        poor estimate trapping the optimiser in a local minimum). With a multiple-scattering
        table, the best of its nodes (the single-scattering fit it is centred on searched the
        grid; outside its nodes the table is clamped). With diffraction the grid
        is scored by the microfacet model alone (the two-scale model costs a few hundred
        microfacet evaluations per point) and only START_REFINE points about its best by the
        full model."""
        if self.orders is not None:
            return self._best_of(np.exp(self.orders.log_alpha))
        if self.diffraction is not None:
            plain = Problem(self.data, self.distribution, self.masking, self.options,
                            self.eta0, self.k, self.optics)
            centre = math.exp(plain.start(alpha0)[0])
            return self._best_of(centre * np.exp(np.linspace(-0.5, 0.5, START_REFINE)))
        return self._best_of(alpha0 * np.exp(np.linspace(-2.5, 2.5, 21)))

    def _best_of(self, grid: np.ndarray) -> np.ndarray:
        """The internal parameters of the lowest chi-square among the alphas of `grid`
        (the other parameters at their starting values)."""
        grid = np.clip(grid, *ALPHA_BOUNDS)
        rest = []
        if self.options.fit_eta:
            rest.append(self.eta0)
        if self.options.fit_scale:
            rest.append(0.0)
        k = 2 if self.options.anisotropic else 1
        trials = [np.array([math.log(a)] * k + rest) for a in grid]
        costs = [float(np.sum(self.residuals(x) ** 2)) for x in trials]
        return np.clip(trials[int(np.argmin(costs))], self.lower + 1e-9, self.upper - 1e-9)


def initial_alpha(data: ReducedData, eta: float) -> float:
    """Roughness from the peak width: the slope of ln f against tan^2 of the half-vector angle
    over the core of the lobe holding the largest value, which is -1/alpha^2 for Beckmann. The
    core is the points above 1 % of the peak, widened to 0.1 % and 0.01 % when fewer than three
    distinct angles fall in it (a narrow peak sampled coarsely)."""
    h = np.where(data.transmission[:, None], -(data.wi + eta * data.wo), data.wi + data.wo)
    h = h / np.linalg.norm(h, axis=1, keepdims=True)
    h = np.where(h[:, 2:3] < 0, -h, h)
    tan2 = (h[:, 0] ** 2 + h[:, 1] ** 2) / np.maximum(h[:, 2] ** 2, 1e-12)
    f = data.bsdf
    k = int(np.argmax(f))
    same_lobe = ((data.transmission == data.transmission[k])
                 & (np.abs(data.theta_i_deg - data.theta_i_deg[k]) < 0.5))
    for level in (1e-2, 1e-3, 1e-4):
        core = same_lobe & (f > level * f[k])
        if len(np.unique(np.round(tan2[core], 12))) >= 3:
            slope = np.polyfit(tan2[core], np.log(f[core]), 1)[0]
            if slope < 0:
                return float(np.clip(1.0 / math.sqrt(-slope), *ALPHA_BOUNDS))
    spread = np.sqrt(tan2[same_lobe & (f > 0.5 * f[k])].max())
    return float(np.clip(max(spread, 1e-3), *ALPHA_BOUNDS))
