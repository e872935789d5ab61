"""A running fit's progress lines: the candidate, its stage, model evaluations so far, the best
chi-square per point and the elapsed time (a diffraction fit evaluates for minutes)."""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Protocol

import numpy as np


class Problem(Protocol):
    """What a progress line names of a fit's candidate (calibration.fit.problem.Problem)."""

    distribution: str
    masking: str

#: Seconds between progress lines of a fit (a diffraction fit evaluates for minutes).
PROGRESS_EVERY_S = 5.0


class Progress:
    """Reports a running fit in one line at most every `every_s` seconds: the candidate, its
    stage, model evaluations so far, the best chi-square per point and the elapsed time."""

    def __init__(self, report: Callable[[str], None] | None, every_s: float = PROGRESS_EVERY_S):
        self.report, self.every_s = report, every_s
        self.started = self.last = time.perf_counter()
        self.evaluations, self.best = 0, math.inf

    def stage(self, problem: Problem, what: str) -> None:
        """A new stage of one candidate (always reported)."""
        self.evaluations, self.best = 0, math.inf
        self._say(f"{problem.distribution}/{problem.masking}: {what}")

    def evaluated(self, problem: Problem, residuals: np.ndarray) -> None:
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
