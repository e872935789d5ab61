"""One candidate of a model family beside the microfacet interface (model.bsdf.families: its
name and fixed settings, e.g. lambert+microfacet with a GGX coat) as a least-squares problem
over the family's PARAMETERS: log where a parameter says so, its bounds, the same instrument
averaging (Smearing) and whitened residuals as the microfacet Problem, solved and summarised by
calibration.fit.solve."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from calibration.fit.options import SCALE_BOUNDS, FitOptions
from calibration.fit.progress import Progress
from calibration.fit.solve import Solution, optimise, summarise
from calibration.reduced import ReducedData
from calibration.smearing import Smearing

#: Where a log parameter without finite bounds (ABg's A and B) is kept: its log stays finite.
LOG_RANGE = (1e-10, 1e10)
#: Trial values per parameter of the start's coordinate search.
START_TRIALS = 9


class FamilyProblem:
    """A family candidate as a least-squares problem in internal parameters (log of a log
    parameter), with `fixed` parameters held at their values and, with FitOptions.fit_scale,
    an overall log scale; a parameter the BSDF is proportional to (Lambert's rho, ABg's A:
    `level`), which a scale factor could not be told from, is then held at the family's
    default, so that the scale carries the data's level."""

    orders = None  # no multiple-scattering table: what calibration.fit.solve asks of a problem

    def __init__(self, data: ReducedData, family: str, settings: Mapping[str, Any],
                 fixed: Mapping[str, float], options: FitOptions, optics: Smearing,
                 progress: Progress | None = None):
        from model.bsdf.families import family_class

        self.data, self.family, self.settings = data, family, dict(settings)
        self.fixed, self.options, self.optics = dict(fixed), options, optics
        self.progress = progress if progress is not None else Progress(None)
        # what progress lines and the solver's errors name the candidate by
        self.distribution = family
        self.masking = "/".join(str(v) for v in self.settings.values()) or "-"
        self.free = tuple(p for p in family_class(family).PARAMETERS if p.name not in fixed)
        self.scaled = False
        self.level = self._level_parameter() if options.fit_scale else None
        if self.level is not None:  # held at its default: the scale carries the level
            self.fixed[self.level] = self.values(self.default_start())[self.level]
            self.free = tuple(p for p in self.free if p.name != self.level)
        self.scaled = options.fit_scale
        names = [p.name for p in self.free]
        lower = [self._internal(p, max(p.lower, LOG_RANGE[0]) if p.log else p.lower)
                 for p in self.free]
        upper = [self._internal(p, min(p.upper, LOG_RANGE[1]) if p.log else p.upper)
                 for p in self.free]
        if self.scaled:
            names.append("scale")
            lower.append(math.log(SCALE_BOUNDS[0]))
            upper.append(math.log(SCALE_BOUNDS[1]))
        self.names = tuple(names)
        self.lower, self.upper = np.array(lower, float), np.array(upper, float)
        self.sigma = data.sigma

    @staticmethod
    def _internal(parameter: Any, value: float) -> float:
        return math.log(value) if parameter.log else value

    def values(self, x: np.ndarray) -> dict[str, float]:
        """The family's parameter values by name (the free ones from x, the fixed ones)."""
        free = {p.name: math.exp(v) if p.log else float(v)
                for p, v in zip(self.free, x, strict=False)}
        return {**free, **self.fixed}

    def model(self, x: np.ndarray) -> Any:
        """The family's model.bsdf model at internal parameters x (without the scale)."""
        from model.bsdf.families import make_family

        return make_family(self.family, self.values(x), **self.settings)

    def scale(self, x: np.ndarray) -> float:
        """The overall scale factor at x (1 when not fitted)."""
        return math.exp(x[-1]) if self.scaled else 1.0

    def external(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Parameter values in `names` order and d(external)/d(internal) on the diagonal."""
        logs = [p.log for p in self.free] + ([True] if self.scaled else [])
        values = np.array([math.exp(v) if log else float(v) for v, log in zip(x, logs,
                                                                               strict=True)])
        return values, np.where(logs, values, 1.0)

    def predict(self, x: np.ndarray, data: ReducedData) -> np.ndarray:
        """The model at the data's pairs, averaged as the instrument averages a reading."""
        return self.predict_with_error(x, data)[0]

    def predict_with_error(self, x: np.ndarray, data: ReducedData
                           ) -> tuple[np.ndarray, np.ndarray]:
        """predict() and the model's own error (0: the families evaluate in closed form)."""
        f = self.scale(x) * self.optics.average(self.model(x), data.wi, data.wo)
        return f, np.zeros_like(f)

    def residuals(self, x: np.ndarray) -> np.ndarray:
        """The fitted points' whitened residuals at x (a non-finite one, or parameters the
        family refuses, count as 1e6)."""
        try:
            r = self.data.whitened(self.predict(x, self.data), self.sigma)
        except ValueError:  # a combination the family refuses (ABg's B at its floor with g)
            r = np.full(len(self.data.bsdf), 1e6)
        r = np.where(np.isfinite(r), r, 1e6)
        self.progress.evaluated(self, r)
        return r

    def _level_parameter(self) -> str | None:
        """The free parameter the BSDF is proportional to at the fitted points (halving it
        halves f), if any: a scale factor beside it could not be told from it."""
        x = self.default_start()
        base = self.predict(x, self.data)
        for k, p in enumerate(self.free):
            trial = x.copy()
            half = 0.5 * self.values(x)[p.name]
            if not p.lower <= half <= p.upper:
                continue
            trial[k] = self._internal(p, half)
            if np.allclose(self.predict(trial, self.data), 0.5 * base, rtol=1e-9, atol=0.0):
                return p.name
        return None

    def default_start(self) -> np.ndarray:
        """The family's default parameter values (its constructor's), as internal parameters,
        with a scale of 1."""
        from model.bsdf.families import family_class

        defaults = family_class(self.family)(**self.settings).parameters()
        x = [self._internal(p, defaults[p.name]) for p in self.free]
        return np.array(x + ([0.0] if self.scaled else []), float)

    def start(self) -> np.ndarray:
        """Where the optimiser starts: from the family's defaults, one pass over the
        parameters, each set to the best of START_TRIALS values across its range (log-spaced
        for a log parameter) with the others held (a guard against a default far off)."""
        x = np.clip(self.default_start(), self.lower + 1e-9, self.upper - 1e-9)
        cost = float(np.sum(self.residuals(x) ** 2))
        for k in range(len(x)):
            lo, hi = self.lower[k] + 1e-9, self.upper[k] - 1e-9
            if not (math.isfinite(lo) and math.isfinite(hi)):
                lo, hi = x[k] - 5.0, x[k] + 5.0
            for value in np.linspace(lo, hi, START_TRIALS):
                trial = x.copy()
                trial[k] = value
                trial_cost = float(np.sum(self.residuals(trial) ** 2))
                if trial_cost < cost:
                    x, cost = trial, trial_cost
        return x


def solve_family(problem: FamilyProblem) -> Solution:
    """The family candidate's least-squares solution from its start."""
    problem.progress.stage(problem, "start")
    return summarise(problem, optimise(problem, problem.start()))
