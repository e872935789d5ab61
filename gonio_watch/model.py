"""The model curves the live view draws over the reduced BSDF: for a run whose devices were all
emulated, the emulator's truth as `gonio plot` draws it (calibration.plot.truth_curves, which
gets the [sim] table only through gonio.record.emulator_config, by way of the reduction's
meta, and the truth from calibration.emulator_truth); no curve for any other run. Each panel's
curves are computed once."""

from __future__ import annotations

import threading
from typing import Any

import numpy as np

from calibration.plot import emulated_truth, truth_curves

NO_MODEL = ("no reference model: the run was not measured on an all-emulated bench "
            "(`gonio fit RUN` fits one)")
DIGITS = 5  # significant digits of the curves sent


def _rounded(values: np.ndarray, positive: bool = False) -> list[float | None]:
    """Values to DIGITS significant digits; None where not finite (or, `positive`, <= 0:
    nothing to draw on a log scale)."""
    return [float(f"{v:.{DIGITS}g}") if np.isfinite(v) and (v > 0 or not positive) else None
            for v in values]


class ModelCurves:
    """The reference curves of each (incidence, side) panel of a run (thread-safe)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._truth: Any = None
        self._known = False
        self._curves: dict[str, list[dict[str, Any]]] = {}

    def curves(self, meta: dict[str, Any] | None, keys: list[str]) -> dict[str, Any]:
        """{"note", "curves": {key: [{"label", "x", "y"}]}} for the panels `keys`
        ("30|reflection"), given the reduction's meta (None: nothing reduced yet)."""
        if meta is None:
            return {"note": "the run is not reduced yet", "curves": {}}
        with self._lock:
            if not self._known:
                self._truth, self._known = emulated_truth(meta), True
            if self._truth is None:
                return {"note": NO_MODEL, "curves": {}}
            for key in keys:
                if key not in self._curves:
                    theta_i, side = key.split("|")
                    found = truth_curves(meta, self._truth, float(theta_i),
                                         side == "transmission")
                    self._curves[key] = [{"label": label, "x": _rounded(x),
                                          "y": _rounded(y, positive=True)}
                                         for label, (x, y) in found.items()]
            return {"note": "", "curves": {k: self._curves[k] for k in keys}}
