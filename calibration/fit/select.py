"""Model selection across families: every family the sample's kind allows (or FitOptions.families)
fitted on the same subset, each scored by BIC on the fitted points and by chi2/dof on the
held-out ones, the choice a FitResult that names its family and lists every candidate. A sample
whose kind allows the microfacet interface alone is fitted exactly as calibration.fit.fit fits
it. See docs/fitting.md ("Model selection")."""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from calibration.candidates import FAMILIES, MICROFACET
from calibration.fit.family import FamilyProblem, solve_family
from calibration.fit.options import FitError, FitOptions, at_measured_incidence
from calibration.fit.pattern import residual_pattern
from calibration.fit.problem import initial_alpha
from calibration.fit.progress import Progress
from calibration.fit.result import MAX_CHI2_DOF, FitResult
from calibration.fit.run import fit, fitted_subset, heldout_chi2, instrument_optics
from calibration.reduced import ReducedData

#: The families each [sample] kind allows; a kind not listed (an imported file's unknown one)
#: allows every family.
KIND_FAMILIES = {
    "hemisphere": (MICROFACET,),
    "slab": (MICROFACET,),
    "conductor": (MICROFACET,),
    "diffuse": ("lambert", "oren-nayar", "lambert+microfacet", "abg"),
    "coated": ("lambert+microfacet", "abg", "lambert"),
    "reference": ("lambert", "oren-nayar"),
}
#: The criterion candidates are ranked by: chi2 + k ln n (Schwarz's Bayesian criterion).
CRITERION = "BIC"
#: A family's index where none is known (the initial peak-width estimate only).
NOMINAL_ETA = 1.5


def families_for(data: ReducedData, options: FitOptions) -> tuple[str, ...]:
    """The families compared: the options', else those the data's sample kind allows."""
    if options.families is not None:
        return options.families
    return KIND_FAMILIES.get(data.meta.get("kind"), FAMILIES)


def bic(chi2: float, n_params: int, n_points: int) -> float:
    """Schwarz's criterion of a least-squares fit: chi2 + k ln n."""
    return chi2 + n_params * math.log(n_points)


def select(data: ReducedData, options: FitOptions | None = None,
           progress: Callable[[str], None] | None = None) -> FitResult:
    """Fit every family the data's kind allows (families_for) and return the preferred one:
    the lowest BIC among the candidates whose held-out chi2/dof is within MAX_CHI2_DOF (all of
    them when none is, or nothing is held out). The microfacet interface alone is fitted by
    calibration.fit.fit, unchanged. A fit at the default normal incidence of data that hold
    none there is made at their lowest incidence (at_measured_incidence)."""
    started = time.perf_counter()
    options = at_measured_incidence(options or FitOptions(), data)
    families = families_for(data, options)
    if families == (MICROFACET,):
        return with_pattern(fit(data, options, progress), data)
    reporter = Progress(progress)
    scored: list[tuple[dict[str, Any], FitResult]] = []
    failures: list[str] = []
    for family in families:
        try:
            results = ([fit(data, options, progress)] if family == MICROFACET
                       else _family_fits(data, options, family, reporter, failures))
        except FitError as exc:
            failures.append(f"{family}: {exc}")
            continue
        scored += [(_entry(result), result) for result in results]
    if not scored:
        raise FitError("fit: no family fitted: " + "; ".join(failures))
    entry, chosen = _preferred(scored)
    runner_up = min((e["bic"] for e, r in scored if r.family != chosen.family), default=None)
    chosen.preferred_by = None if runner_up is None else runner_up - entry["bic"]
    chosen.criterion = CRITERION
    chosen.candidates = ([e for e, _ in sorted(scored, key=lambda item: item[0]["bic"])]
                         + [{"failed": msg} for msg in failures])
    chosen.fit_time_s = time.perf_counter() - started
    return with_pattern(chosen, data)


def with_pattern(result: FitResult, data: ReducedData) -> FitResult:
    """The result with its residual pattern (calibration.fit.pattern) over the valid points,
    but for a fit with multiple scattering (its predictions walk again; its hint is moot)."""
    if result.walks is None:
        result.residual_pattern = residual_pattern(data, result)
    return result


def _family_fits(data: ReducedData, options: FitOptions, family: str, reporter: Progress,
                 failures: list[str]) -> list[FitResult]:
    """The family fitted once per combination of its fixed settings (_setting_choices), as
    FitResults; each combination that fails is named in `failures`, and those the family does
    not take (a coat of a distribution without kernels) when it takes none."""
    from model.bsdf.families import family_class

    cls = family_class(family)
    eta0 = options.eta if options.eta is not None else data.meta.get("eta")
    fixed = ({"eta": float(eta0)} if eta0 is not None and not options.fit_eta
             and "eta" in {p.name for p in cls.PARAMETERS} else {})
    n_params = len(cls.PARAMETERS) - len(fixed) + options.fit_scale
    in_fit, fit_data = fitted_subset(data, options, n_params)
    positive = fit_data.subset(fit_data.bsdf > 0)
    optics = instrument_optics(data, options, initial_alpha(positive, eta0 or NOMINAL_ETA))
    results, refused = [], []
    choices = _setting_choices(cls, data, options)
    for settings in choices:
        label = "/".join([family, *map(str, settings.values())])
        try:
            cls(**settings)
        except (TypeError, ValueError) as exc:  # a setting it does not take (a phong coat)
            refused.append(f"{label}: {exc}")
            continue
        try:
            problem = FamilyProblem(fit_data, family, settings, fixed, options, optics,
                                    reporter)
            solution = solve_family(problem)
        except (FitError, ValueError) as exc:
            failures.append(f"{label}: {exc}")
            continue
        if solution.at_bound:
            failures.append(f"{label}: {', '.join(solution.at_bound)} ended at its bound (the "
                            "data do not support this model)")
            continue
        held, n_held = heldout_chi2(data, ~in_fit, problem, solution.x)
        results.append(FitResult(
            distribution=settings.get("distribution", ""), masking=settings.get("masking", ""),
            names=problem.names, values=solution.values,
            errors=np.sqrt(np.diag(solution.covariance)), covariance=solution.covariance,
            eta=float(problem.fixed.get("eta", math.nan)), k=None,
            chi2_dof_fit=solution.chi2_dof, n_fit=int(in_fit.sum()), chi2_dof_heldout=held,
            n_heldout=n_held, preferred_by=None, optics=optics, family=family,
            settings=settings, fixed=problem.fixed))
    if len(refused) == len(choices):
        failures += refused
    return results


def _setting_choices(cls: type, data: ReducedData, options: FitOptions) -> list[dict]:
    """Every combination of a family's fixed settings: its distribution and masking each a
    candidate from the options' (as the microfacet fit's are), another setting the data's
    meta entry of that name (a wavelength, the sample's index: the options' eta if given) or
    the family's default."""
    choices = {"distribution": options.distributions, "masking": options.maskings}
    axes = [(name, choices[name]) for name in cls.SETTINGS if name in choices]
    meta = {**data.meta, **({"eta": options.eta} if options.eta is not None else {})}
    given = {name: meta[name] for name in cls.SETTINGS
             if name not in choices and meta.get(name) is not None}
    names = [name for name, _ in axes]
    return [{**dict(zip(names, combo, strict=True)), **given}
            for combo in itertools.product(*(values for _, values in axes))]


def _entry(result: FitResult) -> dict[str, Any]:
    """A candidate as the result lists it: family, settings, both scores, parameters."""
    n_params = len(result.names)
    chi2 = result.chi2_dof_fit * (result.n_fit - n_params)
    params = {n: {"value": float(v), "sigma": float(e)}
              for n, v, e in zip(result.names, result.values, result.errors, strict=True)}
    return {"family": result.family, "distribution": result.distribution,
            "masking": result.masking, "settings": result.settings,
            "chi2_dof_fit": result.chi2_dof_fit, "n_fit": result.n_fit,
            "chi2_dof_heldout": result.chi2_dof_heldout, "n_heldout": result.n_heldout,
            "bic": bic(chi2, n_params, result.n_fit), "parameters": params}


def _preferred(scored: list[tuple[dict[str, Any], FitResult]]
               ) -> tuple[dict[str, Any], FitResult]:
    """The lowest BIC among the candidates the held-out points do not refute (held-out
    chi2/dof within MAX_CHI2_DOF, or none held out); among all when every one is refuted."""
    kept = [(e, r) for e, r in scored
            if e["chi2_dof_heldout"] is None or e["chi2_dof_heldout"] <= MAX_CHI2_DOF]
    return min(kept or scored, key=lambda item: item[0]["bic"])
