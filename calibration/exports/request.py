"""What an export writes and how it reduces and fits the run (calibration.exports.write)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from calibration.exports.bird_supplement import Supplement
    from calibration.fit import FitOptions


@dataclass(frozen=True)
class ExportRequest:
    """What to export (None: the format's default) and how to reduce and fit the run."""

    what: str | None = None
    fit_options: FitOptions | None = None
    fit_file: str | Path | None = None  # `gonio fit --json` output to export instead of fitting
    force: bool = False  # read a damaged run's valid readings (gonio.store.Run); export a fit
    # whose chi2/dof says it does not describe the data
    calibration: str | Path | None = None
    shot_noise_w: float | None = None
    subtract_signature: bool = False
    angle_terms: bool = True  # False: reduce without the budget's angle terms (U says so)
    single_scattering: bool = False  # Mitsuba: drop a fit's multiple scattering (and say so)
    provenance: Supplement | None = None  # BiRD: what the run lacks, given at export time
