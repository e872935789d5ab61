"""One candidate's least-squares solution: the optimiser from the best start, the
multiple-scattering table built and recentred about it, the preferred candidate's refit, and the
solution's parameters, covariance and chi-square as a typed Solution."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import OptimizeResult, least_squares

from calibration.fit.model import build_model
from calibration.fit.options import FitError
from calibration.fit.orders import MS_CENTRE_WALKS, MS_TABLE_RECENTRE, OrdersTable
from calibration.fit.problem import Problem

# Singular-value ratio of the weighted Jacobian beyond which a parameter is unconstrained.
MAX_CONDITION = 1e6


@dataclass(frozen=True)
class Solution:
    """One candidate's fit: the internal parameters x, the parameters' values and covariance,
    chi-square in total and per degree of freedom, the parameters that ended at a bound, and
    the optimiser's result (which `refine` continues from)."""

    x: np.ndarray
    values: np.ndarray
    covariance: np.ndarray
    chi2: float
    chi2_dof: float
    at_bound: tuple[str, ...]
    optimum: OptimizeResult


def solve(problem: Problem, alpha0: float) -> Solution:
    """Run one candidate's fit from the best start about alpha0 (with multiple scattering,
    through its first table: `recentre` goes on from there)."""
    if problem.options.multiple_scattering:
        optimum = _solve_with_orders(problem, alpha0)
    else:
        optimum = _least_squares(problem, alpha0)
    return summarise(problem, optimum)


def refine(problem: Problem, solution: Solution) -> Solution:
    """The preferred candidate refitted with its multiple-scattering term at the result walked
    MS_CENTRE_WALKS times over (the table keeps the slope), again while the result moves more
    than MS_CENTRE_REACH steps from where that was walked: the fitted model's own error is
    then that of MS_CENTRE_WALKS x ms_walks walks."""
    walks = problem.options.ms_walks * MS_CENTRE_WALKS
    optimum = solution.optimum
    for _ in range(MS_TABLE_RECENTRE):
        alpha = problem.unpack(optimum.x)[0]
        problem.progress.stage(problem, f"multiple-scattering term at alpha {alpha:.5g} by "
                               f"{walks} walks")
        problem.orders.refine(problem, alpha)
        optimum = _least_squares(problem, alpha)
        if problem.orders.covers(problem.unpack(optimum.x)[0]):
            break
    return summarise(problem, optimum)


def _least_squares(problem: Problem, alpha0: float) -> OptimizeResult:
    """The optimiser's solution from the best start about alpha0, each point weighed by the
    problem's sigma (with a table, its error added)."""
    problem.progress.stage(problem, "start" if problem.orders is None
                           else "start with the multiple-scattering table")
    return optimise(problem, problem.start(alpha0))


def optimise(problem, x0: np.ndarray) -> OptimizeResult:
    """The optimiser's solution of a least-squares problem (a Problem, or any with its
    residuals, lower and upper) from the internal parameters x0."""
    return least_squares(problem.residuals, x0, bounds=(problem.lower, problem.upper),
                         method="trf", x_scale="jac", xtol=1e-12, ftol=1e-12, gtol=1e-12,
                         max_nfev=400)


def recentre(problem: Problem, solution: Solution) -> Solution:
    """A multiple-scattering fit (solve's) redone with its table rebuilt about the result while
    that falls outside the table's inner nodes, MS_TABLE_RECENTRE tables in all at most."""
    optimum = solution.optimum
    for _ in range(MS_TABLE_RECENTRE - 1):
        alpha = problem.unpack(optimum.x)[0]
        if problem.orders.covers(alpha):
            break
        optimum = _table_fit(problem, alpha)
    return solution if optimum is solution.optimum else summarise(problem, optimum)


def _table_fit(problem: Problem, centre: float) -> OptimizeResult:
    """The fit with a multiple-scattering table built about centre. Each point's sigma gains
    the table's Monte Carlo error in quadrature (the model's own uncertainty)."""
    problem.progress.stage(problem, f"multiple-scattering table about alpha {centre:.4g}")
    problem.orders = OrdersTable(problem, centre)
    return _least_squares(problem, centre)


def _solve_with_orders(problem: Problem, alpha0: float) -> OptimizeResult:
    """The fit with the multiple-scattering table built about the single-scattering fit's
    alpha (within a few % of the answer). A distribution the walk cannot walk on is refused
    before its single-scattering fit."""
    from model.bsdf.multiple_scattering.walk import walkable

    walkable(build_model(problem.distribution, alpha0, problem.eta0, "correlated",
                         problem.k).distribution)
    single = Problem(problem.data, problem.distribution, problem.masking,
                     replace(problem.options, multiple_scattering=False), problem.eta0,
                     problem.k, problem.optics, problem.diffraction, problem.progress)
    return _table_fit(problem, single.unpack(_least_squares(single, alpha0).x)[0])


def summarise(problem: Problem, optimum: OptimizeResult) -> Solution:
    """Parameters, covariance and chi-square of an optimiser's solution (of a Problem, or of
    any problem with its data, names, bounds, orders, external() and a `distribution` label)."""
    if not np.all(np.isfinite(optimum.x)) or optimum.status <= 0:
        raise FitError(f"fit {problem.distribution}: the optimiser did not converge "
                       f"({optimum.message})")
    # optimum.fun also holds the shared errors' priors
    n, p = len(problem.data.bsdf), len(optimum.x)
    chi2 = float(np.sum(optimum.fun ** 2))
    dof = n - p
    jac = optimum.jac
    _check_conditioning(jac, problem.names, problem.distribution)
    cov_internal = np.linalg.inv(jac.T @ jac)
    values, deriv = problem.external(optimum.x)
    margin = np.minimum(optimum.x - problem.lower, problem.upper - optimum.x)
    at_bound = tuple(nm for nm, m, xv in zip(problem.names, margin, optimum.x, strict=True)
                     if m < 1e-6 * max(1.0, abs(xv)))
    chi2_dof = chi2 / dof
    cov_internal = cov_internal * max(1.0, chi2_dof)
    if problem.orders is not None:
        cov_internal = cov_internal + _orders_covariance(problem, optimum.x, jac)
    cov = cov_internal * np.outer(deriv, deriv)
    return Solution(x=optimum.x, values=values, covariance=cov, chi2=chi2, chi2_dof=chi2_dof,
                    at_bound=at_bound, optimum=optimum)


def _orders_covariance(problem: Problem, x: np.ndarray, jac: np.ndarray) -> np.ndarray:
    """Covariance of the internal parameters due to the multiple-scattering table's Monte Carlo
    error (correlated between the points walked together), propagated linearly through the
    least-squares solution: G C G^T, G = (J^T J)^-1 J_data^T diag(scale / sigma)."""
    n = len(problem.data.bsdf)
    weight = problem.unpack(x)[2] / problem.sigma
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
