"""Fit microfacet model parameters to reduced BSDF data by weighted least squares.

The model is `model.bsdf.RoughDielectric` (distribution, alpha or (alpha_x, alpha_y), eta,
masking form) times an optional scale factor. Fits run on a chosen subset (by default normal
incidence only, as Walter et al. 2007 did) and the fitted model then predicts the rest, so
the held-out chi-square tests the model rather than the fit. See docs/fitting.md.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from calibration.candidates import DISTRIBUTION_NAMES, MASKINGS
from calibration.reduced import ReducedData
from calibration.smearing import Smearing, smearing_order
from gonio.errors import GonioError

ALPHA_BOUNDS = (1e-4, 4.0)
ETA_BOUNDS = (1.001, 4.0)
SCALE_BOUNDS = (1e-3, 1e3)
# Singular-value ratio of the weighted Jacobian beyond which a parameter is unconstrained.
MAX_CONDITION = 1e6
# A distribution is "preferred" only if it beats the next by this chi-square (2 sigma for one
# extra degree of freedom); otherwise the result says the data cannot tell them apart.
PREFERENCE_DELTA_CHI2 = 4.0
# The multiple-scattering table of a fit: NODES alphas STEP apart in log alpha about a centre;
# a fit ending outside its inner nodes is redone about its result, at most RECENTRE times. The
# preferred candidate is then refitted with the term at its result walked CENTRE_WALKS times
# FitOptions.ms_walks (the fitted model's value), again while it ends more than CENTRE_REACH
# steps from where that was walked.
MS_TABLE_STEP = 0.1
MS_TABLE_NODES = 7
MS_TABLE_RECENTRE = 3
MS_CENTRE_WALKS = 16
MS_CENTRE_REACH = 0.25
# Points whose refitted term's error exceeds MS_REWALK_SIGMA of their data sigma are walked
# again with MS_REWALK_WALKS times the refit's walks (the transmitted wings at normal incidence):
# the worst point's error falls 1.21 -> 0.85 data sigma on the acid-etched run, +0.8-1.7 s a fit.
MS_REWALK_SIGMA = 0.6
MS_REWALK_WALKS = 1
MS_WALKS_MAX = 1 << 22
# Points of the two-scale model's lobe integral per pair: the bench's (sim.bench.sample), so a
# fit of an emulated run evaluates the same fixed point set.
DIFFRACTION_SAMPLES = 256
# Alphas about the microfacet model's best start at which a diffraction fit scores its own.
START_REFINE = 5


class FitError(GonioError):
    """A fit failed, is ill-conditioned, or was asked of data that cannot support it."""


#: Seconds between progress lines of a fit (a diffraction fit evaluates for minutes).
PROGRESS_EVERY_S = 5.0


class _Progress:
    """Reports a running fit in one line at most every `every_s` seconds: the candidate, its
    stage, model evaluations so far, the best chi-square per point and the elapsed time."""

    def __init__(self, report: Callable[[str], None] | None, every_s: float = PROGRESS_EVERY_S):
        self.report, self.every_s = report, every_s
        self.started = self.last = time.perf_counter()
        self.evaluations, self.best = 0, math.inf

    def stage(self, problem: _Problem, what: str) -> None:
        """A new stage of one candidate (always reported)."""
        self.evaluations, self.best = 0, math.inf
        self._say(f"{problem.distribution}/{problem.masking}: {what}")

    def evaluated(self, problem: _Problem, residuals: np.ndarray) -> None:
        """One model evaluation (reported when every_s has passed since the last line)."""
        self.evaluations += 1
        self.best = min(self.best, float(np.sum(residuals ** 2)) / max(len(residuals), 1))
        if time.perf_counter() - self.last >= self.every_s:
            self._say(f"{problem.distribution}/{problem.masking}: {self.evaluations} model "
                      f"evaluations, best chi2/point {self.best:.4g}")

    def _say(self, text: str) -> None:
        self.last = time.perf_counter()
        if self.report is not None:
            self.report(f"fit: {text} ({self.last - self.started:.0f} s)")


@dataclass(frozen=True)
class FitOptions:
    """What to fit: the candidate distributions and masking forms (the best is reported),
    which parameters are free, and which points form the fitted subset."""

    distributions: tuple[str, ...] = DISTRIBUTION_NAMES
    maskings: tuple[str, ...] = ("separable",)
    anisotropic: bool = False
    fit_eta: bool = False
    fit_scale: bool = False
    eta: float | None = None  # fixed (or starting) eta; None: the data's meta["eta"]
    k: float | None = None  # conductor extinction (fixed); None: meta["k"] if meta["kind"] is
    #                         "conductor", else a dielectric
    fit_incidence_deg: tuple[float, ...] | None = (0.0,)  # None: fit every valid point
    incidence_tol_deg: float = 0.5
    aperture_half_angle_deg: float | None = None  # None: meta's, if any; 0: point model
    aperture_order: int | None = None  # radial nodes of the aperture rule; None: from the lobe
    beam_divergence_deg: float | None = None  # half-angle; None: meta's, if any; 0: none
    multiple_scattering: bool = False  # add the random walk's orders >= 2 to the model
    ms_walks: int = 1 << 17  # walks per incidence and table alpha (the refit: x MS_CENTRE_WALKS)
    ms_seed: int = 0
    diffraction: bool = False  # the two-scale model (Holzschuch-Pacanowski) around the trial one
    rms_height_nm: float | None = None  # nano-roughness of the K-correlation PSD (held fixed)
    correlation_length_um: float | None = None
    psd_exponent: float = 2.0
    wavelength_nm: float | None = None  # None: the data's meta["wavelength_nm"]
    diffraction_samples: int = DIFFRACTION_SAMPLES

    def __post_init__(self) -> None:
        if self.diffraction:
            _check_diffraction_options(self)
        if isinstance(self.ms_walks, bool) or not isinstance(self.ms_walks, int) \
                or not 2 <= self.ms_walks <= MS_WALKS_MAX:
            raise FitError(f"fit: ms_walks must be an integer in [2, {MS_WALKS_MAX}], "
                           f"got {self.ms_walks!r}")
        if self.multiple_scattering and self.anisotropic:
            raise FitError("fit: multiple_scattering is tabulated against one alpha; it cannot "
                           "be combined with anisotropic")
        for name, given, known in (("distribution", self.distributions, DISTRIBUTION_NAMES),
                                   ("masking", self.maskings, MASKINGS)):
            if not given:
                raise FitError(f"fit: at least one {name} is needed")
            for value in given:
                if value not in known:
                    raise FitError(f"fit: unknown {name} {value!r}; known: {', '.join(known)}")
        if self.eta is not None and not ETA_BOUNDS[0] <= self.eta <= ETA_BOUNDS[1]:
            raise FitError(f"fit: eta must be in [{ETA_BOUNDS[0]}, {ETA_BOUNDS[1]}], "
                           f"got {self.eta!r}")


@dataclass(frozen=True)
class Diffraction:
    """Held-fixed nano-roughness and wavelength of a fit's two-scale diffraction term."""

    rms_height_nm: float
    correlation_length_um: float
    psd_exponent: float
    wavelength_nm: float
    samples: int = DIFFRACTION_SAMPLES

    def wrap(self, model: Any) -> Any:
        """The two-scale model (model.bsdf.diffraction.TwoScaleDiffraction) around `model`, with
        eval(wi, wo) at this wavelength."""
        return _Diffracted(model, self)

    def to_dict(self) -> dict[str, float]:
        """The settings as a JSON-ready dict."""
        return {"rms_height_nm": self.rms_height_nm,
                "correlation_length_um": self.correlation_length_um,
                "psd_exponent": self.psd_exponent, "wavelength_nm": self.wavelength_nm,
                "samples": self.samples}


class _Diffracted:
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


def _check_diffraction_options(options: FitOptions) -> None:
    """Raise FitError naming what a diffraction fit lacks or cannot combine with."""
    missing = [name for name in ("rms_height_nm", "correlation_length_um")
               if getattr(options, name) is None]
    if missing:
        raise FitError(f"fit: diffraction needs the nano-roughness {' and '.join(missing)} "
                       "(--rms-height-nm and --correlation-length-um; an all-emulated "
                       "run's [sim.sample] gives them)")
    for name in ("rms_height_nm", "correlation_length_um", "wavelength_nm"):
        value = getattr(options, name)
        if value is not None and not (math.isfinite(value) and value > 0):
            raise FitError(f"fit: {name} must be positive and finite, got {value!r}")
    if not (math.isfinite(options.psd_exponent) and options.psd_exponent > 1):
        raise FitError(f"fit: psd_exponent must be finite and > 1, got {options.psd_exponent!r}")
    samples = options.diffraction_samples
    if isinstance(samples, bool) or not isinstance(samples, int) or samples < 2 or samples % 2:
        raise FitError(f"fit: diffraction_samples must be an even integer >= 2, got {samples!r}")


def diffraction_settings(data: ReducedData, options: FitOptions) -> Diffraction | None:
    """The fit's diffraction term from the options and the data's wavelength; None when off."""
    if not options.diffraction:
        return None
    wavelength = options.wavelength_nm
    if wavelength is None:
        wavelength = data.meta.get("wavelength_nm")
    if wavelength is None:
        raise FitError("fit: diffraction needs the wavelength; the data carry no "
                       "meta['wavelength_nm'] and none was given")
    return Diffraction(float(options.rms_height_nm), float(options.correlation_length_um),
                       float(options.psd_exponent), float(wavelength),
                       options.diffraction_samples)


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
    diffraction: Diffraction | None = None  # the two-scale term the fit used; None: off
    fit_time_s: float = 0.0  # wall time of fit()

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
        term the fit used, if any."""
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
        single = build_model(self.distribution, self.alpha, self.eta, self.masking, self.k,
                             diffraction=self.diffraction)
        f = self.optics.average(single, wi, wo)
        err = np.zeros_like(f)
        if self.walks is not None:
            orders, err, _ = walked_orders(self.distribution, self.alpha, self.eta, self.k, wi,
                                           wo, self.walks, self.seed)
            f = f + orders
        return self.scale * f, abs(self.scale) * err

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready summary (what `gonio fit --json` prints)."""
        params = {n: {"value": float(v), "sigma": float(e)}
                  for n, v, e in zip(self.names, self.values, self.errors, strict=True)}
        if "eta" not in params:
            params["eta"] = {"value": self.eta, "sigma": 0.0, "fixed": True}
        if self.k is not None:
            params["k"] = {"value": self.k, "sigma": 0.0, "fixed": True}
        if self.distribution == "phong":
            a = np.atleast_1d(self.alpha)
            params["phong_exponent"] = {"value": float(2.0 / (a[0] * a[-1]) - 2.0)}
        return {
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
                                          "fitted_walks": self.walks * MS_CENTRE_WALKS}),
            "diffraction": None if self.diffraction is None else self.diffraction.to_dict(),
            "fit_time_s": self.fit_time_s,
            "candidates": self.candidates,
        }


class _WithHigherOrders:
    """A single-scattering model plus the random walk's orders >= 2 on the same microsurface
    (model.bsdf.multiple_scattering.higher_orders_at: walked at the pairs, fixed seed)."""

    def __init__(self, single: Any, correlated: Any, walks: int, seed: int):
        self.single, self.correlated = single, correlated
        self.walks, self.seed = walks, seed

    def eval(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """f(wi, wo) in 1/sr: single scattering plus orders >= 2."""
        from model.bsdf.multiple_scattering import higher_orders_at

        wi, wo = np.broadcast_arrays(wi, wo)
        extra = higher_orders_at(self.correlated, wi, wo, self.walks, self.seed,
                                 covariance=False)[0]
        return self.single.eval(wi, wo) + extra.reshape(wi.shape[:-1])


class _OrdersTable:
    """Orders >= 2 at the fitted points (higher_orders_at: walked at the points themselves, one
    set of walks per incidence) at MS_TABLE_NODES alphas MS_TABLE_STEP apart in log alpha about
    `centre`, all from one seed, and a cubic spline in log alpha through them (clamped at the
    ends): a deterministic, smooth term for the optimiser. `refine` adds a constant so that
    the term at one alpha is its value walked MS_CENTRE_WALKS times over (the spline keeps the
    slope). `error` and `covariance` are the Monte Carlo standard error per point and their
    covariance (points of one incidence share walks) at the centre node, or where refined."""

    def __init__(self, problem: _Problem, centre: float):
        from scipy.interpolate import CubicSpline

        half = 0.5 * (MS_TABLE_NODES - 1)
        self.log_alpha = math.log(centre) + (np.arange(MS_TABLE_NODES) - half) * MS_TABLE_STEP
        walks = problem.options.ms_walks
        walked = [_walked_orders(problem, math.exp(a), walks, node == MS_TABLE_NODES // 2,
                                 both_ways=False) for node, a in enumerate(self.log_alpha)]
        self.spline = CubicSpline(self.log_alpha, np.array([w[0] for w in walked]), axis=0)
        _, self.error, self.covariance = walked[MS_TABLE_NODES // 2]
        self.offset, self.refined_at = 0.0, None

    def __call__(self, alpha: float) -> np.ndarray:
        return self.spline(float(np.clip(math.log(alpha), self.log_alpha[0],
                                          self.log_alpha[-1]))) + self.offset

    def refine(self, problem: _Problem, alpha: float) -> None:
        """Walk the term at alpha (refit_orders: MS_CENTRE_WALKS x ms_walks walks, and again
        where that is not below the data's noise) and shift the spline onto it; its error and
        covariance become those."""
        value, self.error, self.covariance = refit_orders(
            problem.distribution, alpha, problem.eta0, problem.k, problem.data.wi,
            problem.data.wo, problem.options.ms_walks * MS_CENTRE_WALKS, problem.options.ms_seed,
            problem.measured.sigma)
        self.offset, self.refined_at = 0.0, math.log(alpha)
        self.offset = value - self(alpha)

    def covers(self, alpha: float) -> bool:
        """True when alpha lies between the second and the last but one node; once refined,
        within MS_CENTRE_REACH steps of where."""
        if self.refined_at is not None:
            return abs(math.log(alpha) - self.refined_at) <= MS_CENTRE_REACH * MS_TABLE_STEP
        return self.log_alpha[1] <= math.log(alpha) <= self.log_alpha[-2]


def _walked_orders(problem: _Problem, alpha: float, walks: int, covariance: bool,
                   both_ways: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """walked_orders at the fitted points for this alpha (the options' seed)."""
    return walked_orders(problem.distribution, alpha, problem.eta0, problem.k, problem.data.wi,
                         problem.data.wo, walks, problem.options.ms_seed, covariance, both_ways)


def walked_orders(distribution: str, alpha: float, eta: float, k: float | None,
                  wi: np.ndarray, wo: np.ndarray, walks: int, seed: int,
                  covariance: bool = False, both_ways: bool = True, stream: int = 0
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Orders >= 2 of the height-correlated microsurface at the pairs, their standard error and,
    if asked, their covariance over the pairs (model.bsdf.multiple_scattering.higher_orders_at,
    both_ways and stream as there), not aperture-averaged (the lobe is broad)."""
    from model.bsdf.multiple_scattering import higher_orders_at

    wi, wo = np.broadcast_arrays(wi, wo)
    value, err, cov = higher_orders_at(build_model(distribution, alpha, eta, "correlated", k),
                                       wi, wo, walks, seed, covariance=covariance,
                                       both_ways=both_ways, stream=stream)
    return value.reshape(wi.shape[:-1]), err.reshape(wi.shape[:-1]), cov


def refit_orders(distribution: str, alpha: float, eta: float, k: float | None,
                 wi: np.ndarray, wo: np.ndarray, walks: int, seed: int, sigma: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The fitted model's orders >= 2 at the pairs, their error and covariance: walked_orders
    with `walks` walks (transmitted pairs in reverse where better), then the pairs whose error
    exceeds MS_REWALK_SIGMA of their data sigma walked again (stream 1) with MS_REWALK_WALKS
    times as many, the two estimates there averaged in proportion to their walks (fixed
    weights: the second estimate is independent of the choice, which rests on the first's own
    error estimate). Pairs the walk cannot tell apart (the same target, so the same first
    estimate) are walked again together, so they keep one value."""
    value, error, cov = walked_orders(distribution, alpha, eta, k, wi, wo, walks, seed,
                                      covariance=True)
    chosen = error > MS_REWALK_SIGMA * sigma
    again = np.flatnonzero(np.isin(value, value[chosen]) & np.isin(error, error[chosen]))
    if len(again):
        more, more_err, more_cov = walked_orders(distribution, alpha, eta, k, wi[again],
                                                 wo[again], walks * MS_REWALK_WALKS, seed,
                                                 covariance=True, stream=1)
        first = 1.0 / (1.0 + MS_REWALK_WALKS)  # the first walks' share of the average
        share = np.ones(len(value))
        share[again] = first
        value[again] = first * value[again] + (1.0 - first) * more
        cov = cov * np.outer(share, share)
        cov[np.ix_(again, again)] += (1.0 - first) ** 2 * more_cov
        error = share * error
        error[again] = np.hypot(error[again], (1.0 - first) * more_err)
    return value, error, cov


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


def fit_subset_mask(data: ReducedData, options: FitOptions) -> np.ndarray:
    """Which points the fit uses: valid, finite, positive sigma, at a chosen incidence."""
    usable = (data.valid & np.isfinite(data.bsdf) & np.isfinite(data.sigma)
              & (data.sigma > 0))
    if options.fit_incidence_deg is None:
        return usable
    theta_i = data.theta_i_deg
    near = np.zeros(len(theta_i), bool)
    for angle in options.fit_incidence_deg:
        near |= np.abs(theta_i - abs(angle)) <= options.incidence_tol_deg
    return usable & near


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


class _Problem:
    """One candidate (distribution, masking) as a least-squares problem in internal parameters:
    log alpha (one or two), eta (if free), log scale (if free)."""

    def __init__(self, data: ReducedData, distribution: str, masking: str, options: FitOptions,
                 eta0: float, k: float | None, optics: Smearing,
                 diffraction: Diffraction | None = None):
        self.data, self.distribution, self.masking = data, distribution, masking
        self.measured = data  # self.data gains the table's error in its sigma; this does not
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
        self.orders: _OrdersTable | None = None
        self.progress = _Progress(None)

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
            walks, seed = _walk_settings(self.options)
            orders, err, _ = walked_orders(self.distribution, alpha, eta, self.k, data.wi,
                                           data.wo, walks, seed)
            f = f + orders
        return scale * f, scale * err

    def residuals(self, x: np.ndarray) -> np.ndarray:
        r = self.data.whitened(self.predict(x, self.data))
        r = np.where(np.isfinite(r), r, 1e6)
        self.progress.evaluated(self, r)
        return r

    def start(self, alpha0: float) -> np.ndarray:
        """Best of a coarse log-alpha grid about the peak-width estimate (a guard against a
        poor estimate trapping the optimiser in a local minimum). With diffraction the grid
        is scored by the microfacet model alone (the two-scale model costs a few hundred
        microfacet evaluations per point) and only START_REFINE points about its best by the
        full model."""
        if self.diffraction is not None:
            plain = _Problem(self.data, self.distribution, self.masking, self.options,
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


def _least_squares(problem: _Problem, alpha0: float) -> Any:
    """The optimiser's solution from the best start about alpha0."""
    problem.progress.stage(problem, "start" if problem.orders is None
                           else "start with the multiple-scattering table")
    return least_squares(problem.residuals, problem.start(alpha0),
                         bounds=(problem.lower, problem.upper), method="trf", x_scale="jac",
                         xtol=1e-12, ftol=1e-12, gtol=1e-12, max_nfev=400)


def _solve_with_orders(problem: _Problem, alpha0: float) -> Any:
    """The fit with the multiple-scattering table: built about the single-scattering fit's
    alpha (within a few % of the answer), and rebuilt about the result while that falls
    outside the table's inner nodes. Each point's sigma gains the table's Monte Carlo error in
    quadrature (the model's own uncertainty)."""
    data = problem.measured
    single = _Problem(data, problem.distribution, problem.masking,
                      replace(problem.options, multiple_scattering=False), problem.eta0,
                      problem.k, problem.optics, problem.diffraction)
    single.progress = problem.progress
    centre = single.unpack(_least_squares(single, alpha0).x)[0]
    for _ in range(MS_TABLE_RECENTRE):
        problem.data = data
        problem.progress.stage(problem, f"multiple-scattering table about alpha {centre:.4g}")
        problem.orders = _OrdersTable(problem, centre)
        sol = _fit_with_table(problem, centre)
        alpha = problem.unpack(sol.x)[0]
        if problem.orders.covers(alpha):
            break
        centre = alpha
    return sol


def _fit_with_table(problem: _Problem, alpha0: float) -> Any:
    """The optimiser's solution with problem.orders, its error added to the points' sigma."""
    problem.data = replace(problem.measured,
                           sigma=np.hypot(problem.measured.sigma, problem.orders.error))
    return _least_squares(problem, alpha0)


def _refine(problem: _Problem, sol: Any) -> dict[str, Any]:
    """The preferred candidate refitted with its multiple-scattering term at the result walked
    MS_CENTRE_WALKS times over (the table keeps the slope), again while the result moves more
    than MS_CENTRE_REACH steps from where that was walked: the fitted model's own error is
    then that of MS_CENTRE_WALKS x ms_walks walks."""
    walks = problem.options.ms_walks * MS_CENTRE_WALKS
    for _ in range(MS_TABLE_RECENTRE):
        alpha = problem.unpack(sol.x)[0]
        problem.progress.stage(problem, f"multiple-scattering term at alpha {alpha:.5g} by "
                               f"{walks} walks")
        problem.data = problem.measured
        problem.orders.refine(problem, alpha)
        sol = _fit_with_table(problem, alpha)
        if problem.orders.covers(problem.unpack(sol.x)[0]):
            break
    return _summary(problem, sol)


def _solve(problem: _Problem, alpha0: float) -> dict[str, Any]:
    """Run one candidate's fit; returns its parameters, covariance and chi-square (with
    multiple scattering also the optimiser's solution, for _refine)."""
    if problem.options.multiple_scattering:
        sol = _solve_with_orders(problem, alpha0)
    else:
        sol = _least_squares(problem, alpha0)
    return _summary(problem, sol)


def _summary(problem: _Problem, sol: Any) -> dict[str, Any]:
    """Parameters, covariance and chi-square of an optimiser's solution."""
    if not np.all(np.isfinite(sol.x)) or sol.status <= 0:
        raise FitError(f"fit {problem.distribution}: the optimiser did not converge "
                       f"({sol.message})")
    n, p = len(problem.data.bsdf), len(sol.x)  # sol.fun also holds the shared errors' priors
    chi2 = float(np.sum(sol.fun ** 2))
    dof = n - p
    jac = sol.jac
    _check_conditioning(jac, problem.names, problem.distribution)
    cov_internal = np.linalg.inv(jac.T @ jac)
    values, deriv = problem.external(sol.x)
    margin = np.minimum(sol.x - problem.lower, problem.upper - sol.x)
    at_bound = [nm for nm, m, xv in zip(problem.names, margin, sol.x, strict=True)
                if m < 1e-6 * max(1.0, abs(xv))]
    chi2_dof = chi2 / dof
    cov_internal = cov_internal * max(1.0, chi2_dof)
    if problem.orders is not None:
        cov_internal = cov_internal + _orders_covariance(problem, sol.x, jac)
    cov = cov_internal * np.outer(deriv, deriv)
    return {"x": sol.x, "values": values, "cov": cov, "chi2": chi2, "chi2_dof": chi2_dof,
            "at_bound": at_bound, "solution": sol}


def _orders_covariance(problem: _Problem, x: np.ndarray, jac: np.ndarray) -> np.ndarray:
    """Covariance of the internal parameters due to the multiple-scattering table's Monte Carlo
    error (correlated between the points walked together), propagated linearly through the
    least-squares solution: G C G^T, G = (J^T J)^-1 J_data^T diag(scale / sigma)."""
    n = len(problem.data.bsdf)
    weight = problem.unpack(x)[2] / problem.data.sigma
    gain = np.linalg.solve(jac.T @ jac, jac[:n].T * weight)
    return gain @ problem.orders.covariance @ gain.T


def _check_conditioning(jac: np.ndarray, names: tuple[str, ...], distribution: str) -> None:
    """Raise FitError naming the parameter(s) the data do not constrain."""
    norms = np.linalg.norm(jac, axis=0)
    dead = [n for n, v in zip(names, norms, strict=True) if not v > 0]
    if dead:
        raise FitError(f"fit {distribution}: the data do not constrain {', '.join(dead)} "
                       "(the model does not change with it at any fitted point)")
    _, s, vt = np.linalg.svd(jac / norms, full_matrices=False)
    if s[-1] <= 0 or s[0] / s[-1] > MAX_CONDITION:
        worst = np.abs(vt[-1])
        involved = [n for n, w in zip(names, worst, strict=True) if w > 0.3]
        raise FitError(f"fit {distribution}: ill-conditioned (condition number "
                       f"{s[0] / max(s[-1], 1e-300):.1e}); the data cannot separate "
                       f"{', '.join(involved)}; fix one of them or add data that constrains it")


def fit(data: ReducedData, options: FitOptions | None = None,
        progress: Callable[[str], None] | None = None) -> FitResult:
    """Fit every candidate (distribution x masking) on the chosen subset, keep the lowest
    chi-square, and score the fitted model on the held-out valid points. progress, if given,
    receives a line per stage and at most every PROGRESS_EVERY_S seconds while it runs."""
    started = time.perf_counter()
    reporter = _Progress(progress)
    options = options or FitOptions()
    diffraction = diffraction_settings(data, options)
    eta0 = options.eta if options.eta is not None else data.meta.get("eta")
    if eta0 is None:
        raise FitError("fit: the data carry no eta (meta['eta']) and none was given")
    eta0 = float(eta0)
    k = options.k
    if k is None and data.meta.get("kind") == "conductor":
        k = float(data.meta.get("k", 0.0))
    if k is not None and options.fit_eta:
        raise FitError("fit: eta of a conductor is held fixed (give it with k); drop fit_eta")
    aperture = options.aperture_half_angle_deg
    if aperture is None:
        aperture = float(data.meta.get("aperture_half_angle_deg", 0.0))
    in_fit = fit_subset_mask(data, options)
    n_params = (2 if options.anisotropic else 1) + options.fit_eta + options.fit_scale
    if in_fit.sum() <= n_params:
        raise FitError(f"fit: only {int(in_fit.sum())} usable points at incidence "
                       f"{_describe_subset(options)}; need more than {n_params}")
    fit_data = data.subset(in_fit)
    if not np.any(fit_data.bsdf > 0):
        raise FitError("fit: no point of the fitted subset has a positive BSDF value")
    alpha0 = initial_alpha(fit_data.subset(fit_data.bsdf > 0), eta0)
    divergence = options.beam_divergence_deg
    if divergence is None:
        divergence = float(data.meta.get("beam_divergence_deg", 0.0))
    order = options.aperture_order
    optics = Smearing(aperture, smearing_order(aperture, alpha0) if order is None else order,
                      divergence, smearing_order(divergence, alpha0))

    scored, failures = [], []
    for distribution in options.distributions:
        for masking in options.maskings:
            problem = _Problem(fit_data, distribution, masking, options, eta0, k, optics,
                               diffraction)
            problem.progress = reporter
            try:
                scored.append((problem, _solve(problem, alpha0)))
            except FitError as exc:
                failures.append(str(exc))
            except ValueError as exc:  # the model refuses the combination (anisotropic phong)
                failures.append(f"fit {distribution}: {exc}")
    if not scored:
        raise FitError("; ".join(failures))
    problem, best = _preferred(scored, options.distributions)
    chi2_ranked = best["chi2"]  # the candidates were ranked with their tables as first walked
    if problem.orders is not None:
        best = _refine(problem, best["solution"])
    if best["at_bound"]:
        raise FitError(f"fit {problem.distribution}: {', '.join(best['at_bound'])} ended at its "
                       "bound; the data do not support this model (check eta, the subset "
                       "and the masked points)")
    runner_up = min((s["chi2"] for p, s in scored if p.distribution != problem.distribution),
                    default=None)
    reporter.stage(problem, "held-out points")
    heldout = _heldout_chi2(data, ~in_fit, problem, best["x"])
    alpha, eta, _ = problem.unpack(best["x"])
    return FitResult(
        distribution=problem.distribution, masking=problem.masking, names=problem.names,
        values=best["values"], errors=np.sqrt(np.diag(best["cov"])), covariance=best["cov"],
        eta=eta, k=k, chi2_dof_fit=best["chi2_dof"], n_fit=int(in_fit.sum()),
        chi2_dof_heldout=heldout[0], n_heldout=heldout[1],
        preferred_by=None if runner_up is None else runner_up - chi2_ranked,
        candidates=[{"distribution": p.distribution, "masking": p.masking,
                     "chi2_dof_fit": s["chi2_dof"],
                     "parameters": dict(zip(p.names, map(float, s["values"]), strict=True))}
                    for p, s in sorted(scored, key=lambda item: item[1]["chi2"])]
        + [{"failed": msg} for msg in failures],
        optics=optics,
        walks=_walk_settings(options)[0], seed=options.ms_seed,
        diffraction=diffraction, fit_time_s=time.perf_counter() - started,
    )


def _walk_settings(options: FitOptions) -> tuple[int | None, int]:
    """(walks, seed) of the multiple-scattering term; walks None when it is off."""
    return (options.ms_walks if options.multiple_scattering else None), options.ms_seed


def _preferred(scored: list[tuple[_Problem, dict[str, Any]]],
               order: tuple[str, ...]) -> tuple[_Problem, dict[str, Any]]:
    """The lowest chi-square; among candidates the data cannot tell apart from it (within
    PREFERENCE_DELTA_CHI2) the first in the listed order, so a narrow Beckmann lobe is not
    reported as its Phong approximation on a noise fluctuation."""
    lowest = min(s["chi2"] for _, s in scored)
    tied = [(p, s) for p, s in scored if s["chi2"] - lowest < PREFERENCE_DELTA_CHI2]
    return min(tied, key=lambda item: (order.index(item[0].distribution), item[1]["chi2"]))


def _heldout_chi2(data: ReducedData, rest: np.ndarray, problem: _Problem,
                  x: np.ndarray) -> tuple[float | None, int]:
    """Chi-square per point of the fitted model on the valid points not used by the fit, with
    the errors they share (the beam curve's) in its covariance."""
    held = rest & fit_subset_mask(data, FitOptions(fit_incidence_deg=None))
    if not held.any():
        return None, 0
    part = data.subset(held)
    model, model_err = problem.predict_with_error(x, part)
    if problem.orders is not None:  # the model's own Monte Carlo error, as in the fit
        part = replace(part, sigma=np.hypot(part.sigma, model_err))
    r = part.whitened(model)
    return float(np.sum(r ** 2)) / int(held.sum()), int(held.sum())


def _describe_subset(options: FitOptions) -> str:
    if options.fit_incidence_deg is None:
        return "any angle"
    return ", ".join(f"{a:g}" for a in options.fit_incidence_deg) + " deg"
