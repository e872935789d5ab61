"""The random walk's orders >= 2 as a fit uses them: walked at the pairs, walked again where
their error is not below the data's noise, and tabulated against alpha for the optimiser."""

from __future__ import annotations

import math
from typing import Protocol

import numpy as np

from calibration.fit.model import build_model
from calibration.fit.options import FitOptions
from calibration.reduced import ReducedData


class Problem(Protocol):
    """What the orders read of a fit's candidate (calibration.fit.problem.Problem): its
    microsurface, its data's directions and sigma, and its walk settings."""

    distribution: str
    eta0: float
    k: float | None
    data: ReducedData
    options: FitOptions

# The multiple-scattering table of a fit: NODES alphas STEP apart in log alpha about a centre;
# a fit ending outside its inner nodes is redone about its result, at most RECENTRE times. The
# preferred candidate is then refitted with the term at its result walked CENTRE_WALKS times
# FitOptions.ms_walks (the fitted model's value), again while it ends more than CENTRE_REACH
# steps from where that was walked.
MS_TABLE_STEP = 0.125
MS_TABLE_NODES = 5
MS_TABLE_RECENTRE = 3
MS_CENTRE_WALKS = 4
MS_CENTRE_REACH = 0.2
# Only candidates whose fit with their first table is within MS_CONTENTION times the best one's
# chi-square (plus PREFERENCE_DELTA_CHI2) have their tables recentred; the others are ranked by
# that fit (on the Walter runs the losers' chi-square is 10^4 times the winner's).
MS_CONTENTION = 4.0
# Points whose refitted term's error exceeds MS_REWALK_SIGMA of their data sigma are walked
# again with MS_REWALK_WALKS times the refit's walks (the transmitted wings at normal incidence):
# the worst point's error falls 1.21 -> 0.85 data sigma on the acid-etched run, +0.8-1.7 s a fit.
MS_REWALK_SIGMA = 0.6
MS_REWALK_WALKS = 1


class OrdersTable:
    """Orders >= 2 at the fitted points (higher_orders_at: walked at the points themselves, one
    set of ms_walks walks per incidence) at MS_TABLE_NODES alphas
    MS_TABLE_STEP apart in log alpha about `centre`, all from one seed, and a cubic spline in
    log alpha through them (clamped at the ends): a deterministic, smooth term for the
    optimiser. `refine` adds a constant so that the term at one alpha is its value walked
    MS_CENTRE_WALKS times over (the spline keeps the slope). `error` and `covariance` are the
    Monte Carlo standard error per point and their covariance (points of one incidence share
    walks) at the centre node, or where refined."""

    def __init__(self, problem: Problem, centre: float):
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

    def refine(self, problem: Problem, alpha: float) -> None:
        """Walk the term at alpha (refit_orders: MS_CENTRE_WALKS x ms_walks walks, and again
        where that is not below the data's noise) and shift the spline onto it; its error and
        covariance become those."""
        value, self.error, self.covariance = refit_orders(
            problem.distribution, alpha, problem.eta0, problem.k, problem.data.wi,
            problem.data.wo, problem.options.ms_walks * MS_CENTRE_WALKS, problem.options.ms_seed,
            problem.data.sigma)
        self.offset, self.refined_at = 0.0, math.log(alpha)
        self.offset = value - self(alpha)

    def covers(self, alpha: float) -> bool:
        """True when alpha lies between the second and the last but one node; once refined,
        within MS_CENTRE_REACH steps of where."""
        if self.refined_at is not None:
            return abs(math.log(alpha) - self.refined_at) <= MS_CENTRE_REACH * MS_TABLE_STEP
        return self.log_alpha[1] <= math.log(alpha) <= self.log_alpha[-2]


def _walked_orders(problem: Problem, alpha: float, walks: int, covariance: bool,
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
