"""fit(): every candidate (distribution x masking) solved on the chosen subset, the preferred one
chosen, refined and scored on the held-out points, as a FitResult. Each candidate's
`chi2_dof_fit` is the one it was ranked by; with multiple scattering the chosen one is refitted
with its term walked MS_CENTRE_WALKS times over (unless FitOptions.ms_slope_only), and its
`chi2_dof_refit` is the result's chi2_dof_fit."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from calibration.fit.options import (
    FitError,
    FitOptions,
    describe_subset,
    diffraction_settings,
    fit_subset_mask,
    walk_settings,
)
from calibration.fit.orders import MS_CONTENTION
from calibration.fit.problem import Problem, initial_alpha
from calibration.fit.progress import Progress
from calibration.fit.result import PREFERENCE_DELTA_CHI2, FitResult
from calibration.fit.solve import Solution, recentre, refine, solve
from calibration.reduced import ReducedData
from calibration.smearing import Smearing, smearing_order


def fit(data: ReducedData, options: FitOptions | None = None,
        progress: Callable[[str], None] | None = None) -> FitResult:
    """Fit every candidate (distribution x masking) on the chosen subset, keep the lowest
    chi-square, and score the fitted model on the held-out valid points. progress, if given,
    receives a line per stage and at most every PROGRESS_EVERY_S seconds while it runs."""
    started = time.perf_counter()
    reporter = Progress(progress)
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
    n_params = (2 if options.anisotropic else 1) + options.fit_eta + options.fit_scale
    in_fit, fit_data = fitted_subset(data, options, n_params)
    alpha0 = initial_alpha(fit_data.subset(fit_data.bsdf > 0), eta0)
    optics = instrument_optics(data, options, alpha0)

    ranking = _ranking(options)
    scored, failures = [], []
    for distribution in ranking.distributions:
        for masking in ranking.maskings:
            problem = Problem(fit_data, distribution, masking, ranking, eta0, k, optics,
                              diffraction, reporter)
            try:
                scored.append((problem, solve(problem, alpha0)))
            except FitError as exc:
                failures.append(str(exc))
            except ValueError as exc:  # the model refuses the combination (anisotropic phong)
                failures.append(f"fit {distribution}: {exc}")
    if not scored:
        raise FitError("; ".join(failures))
    if ranking.multiple_scattering:
        scored = _recentred(scored)
    problem, best = _preferred(scored, options.distributions)
    chi2_ranked = best.chi2  # the candidates were ranked with their tables as first walked
    if ranking is not options:  # the chosen one, with its multiple-scattering term
        problem = Problem(fit_data, problem.distribution, problem.masking, options, eta0, k,
                          optics, diffraction, reporter)
        best = recentre(problem, solve(problem, alpha0))
    refit = {}
    if problem.orders is not None and not options.ms_slope_only:
        best = refine(problem, best)
        refit = {"chi2_dof_refit": best.chi2_dof}  # the chosen one's, as the result gives it
    if best.at_bound:
        raise FitError(f"fit {problem.distribution}: {', '.join(best.at_bound)} ended at its "
                       "bound; the data do not support this model (check eta, the subset "
                       "and the masked points)")
    runner_up = min((s.chi2 for p, s in scored if p.distribution != problem.distribution),
                    default=None)
    reporter.stage(problem, "held-out points")
    heldout = heldout_chi2(data, ~in_fit, problem, best.x)
    alpha, eta, _ = problem.unpack(best.x)
    return FitResult(
        distribution=problem.distribution, masking=problem.masking, names=problem.names,
        values=best.values, errors=np.sqrt(np.diag(best.covariance)),
        covariance=best.covariance, eta=eta, k=k, chi2_dof_fit=best.chi2_dof,
        n_fit=int(in_fit.sum()), chi2_dof_heldout=heldout[0], n_heldout=heldout[1],
        preferred_by=None if runner_up is None else runner_up - chi2_ranked,
        candidates=[{"distribution": p.distribution, "masking": p.masking,
                     "chi2_dof_fit": s.chi2_dof,
                     "parameters": dict(zip(p.names, map(float, s.values), strict=True)),
                     **(refit if p is problem else {})}
                    for p, s in sorted(scored, key=lambda item: item[1].chi2)]
        + [{"failed": msg} for msg in failures],
        optics=optics,
        walks=walk_settings(options)[0], seed=options.ms_seed,
        slope_only=options.ms_slope_only,
        diffraction=diffraction, fit_time_s=time.perf_counter() - started,
    )


def fitted_subset(data: ReducedData, options: FitOptions, n_params: int
                  ) -> tuple[np.ndarray, ReducedData]:
    """(mask, data) of the points a fit of n_params parameters uses; a FitError when they are
    too few or none is positive."""
    in_fit = fit_subset_mask(data, options)
    if in_fit.sum() <= n_params:
        raise FitError(f"fit: only {int(in_fit.sum())} usable points at incidence "
                       f"{describe_subset(options)}; need more than {n_params}")
    fit_data = data.subset(in_fit)
    if not np.any(fit_data.bsdf > 0):
        raise FitError("fit: no point of the fitted subset has a positive BSDF value")
    return in_fit, fit_data


def instrument_optics(data: ReducedData, options: FitOptions, alpha0: float) -> Smearing:
    """What the fit's model of a reading averages over: the aperture and beam divergence the
    options give (else the data's meta, else none), each cap's rule sized for a lobe of
    roughness alpha0 (or the options' aperture order)."""
    aperture = options.aperture_half_angle_deg
    if aperture is None:
        aperture = float(data.meta.get("aperture_half_angle_deg", 0.0))
    divergence = options.beam_divergence_deg
    if divergence is None:
        divergence = float(data.meta.get("beam_divergence_deg", 0.0))
    order = options.aperture_order
    return Smearing(aperture, smearing_order(aperture, alpha0) if order is None else order,
                    divergence, smearing_order(divergence, alpha0))


def _ranking(options: FitOptions) -> FitOptions:
    """The options the candidates are ranked with: a slope-only fit with multiple scattering
    (FitOptions.ms_slope_only) ranks those the walk can walk on by single scattering and adds
    the term to the chosen one only; any other fit, its own options."""
    from model.bsdf.distributions import WALKABLE

    walkable = tuple(d for d in options.distributions if d in WALKABLE)
    if not (options.multiple_scattering and options.ms_slope_only and walkable):
        return options
    return replace(options, multiple_scattering=False, distributions=walkable)


def _recentred(scored: list[tuple[Problem, Solution]]) -> list[tuple[Problem, Solution]]:
    """The candidates in contention (within MS_CONTENTION of the lowest chi-square, plus
    PREFERENCE_DELTA_CHI2) with their multiple-scattering tables recentred; the rest as they
    are, ranked by their first table's fit."""
    lowest = min(s.chi2 for _, s in scored)
    return [(p, recentre(p, s) if s.chi2 <= MS_CONTENTION * lowest + PREFERENCE_DELTA_CHI2
             else s) for p, s in scored]


def _preferred(scored: list[tuple[Problem, Solution]],
               order: tuple[str, ...]) -> tuple[Problem, Solution]:
    """The lowest chi-square; among candidates the data cannot tell apart from it (within
    PREFERENCE_DELTA_CHI2) the first in the listed order, so a narrow Beckmann lobe is not
    reported as its Phong approximation on a noise fluctuation."""
    lowest = min(s.chi2 for _, s in scored)
    tied = [(p, s) for p, s in scored if s.chi2 - lowest < PREFERENCE_DELTA_CHI2]
    return min(tied, key=lambda item: (order.index(item[0].distribution), item[1].chi2))


def heldout_chi2(data: ReducedData, rest: np.ndarray, problem: Problem,
                  x: np.ndarray) -> tuple[float | None, int]:
    """Chi-square per point of the fitted model on the valid points not used by the fit, with
    the errors they share (the beam curve's) in its covariance and, with the fit's
    multiple-scattering term, the model's own Monte Carlo error in each point's sigma."""
    held = rest & fit_subset_mask(data, FitOptions(fit_incidence_deg=None))
    if not held.any():
        return None, 0
    part = data.subset(held)
    model, model_err = problem.predict_with_error(x, part)
    sigma = part.sigma if problem.orders is None else np.hypot(part.sigma, model_err)
    r = part.whitened(model, sigma)
    return float(np.sum(r ** 2)) / int(held.sum()), int(held.sum())
