"""The files of one export: reduced data (or a run's raw readings) and a fit, written by the
format's writer for `what` (calibration.formats; calibration.exports.write's defaults and
choices)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from calibration.exports.request import ExportRequest
from calibration.formats import FORMATS
from calibration.reduced import ReducedData
from gonio.errors import GonioError
from gonio.record import run_record


def write_run(run_dir: str | Path, fmt: str, what: str, out: Path, request: ExportRequest,
              fallback: bool) -> tuple[list[Path], list[str]]:
    """Reduce the run (unless `what` is raw) and write it; with `fallback`, a run that cannot
    be reduced is written raw, with a note saying why."""
    from calibration.pipeline import reduce_run
    from gonio.store import open_run

    run = open_run(run_dir, force=request.force)
    notes: list[str] = []
    if what != "raw":
        try:
            data = reduce_run(run, request.calibration, request.shot_noise_w,
                              request.subtract_signature, angle_terms=request.angle_terms)
        except GonioError as exc:
            if not fallback:
                raise
            notes.append(f"export: the run cannot be reduced ({exc}); wrote its raw readings "
                         "(--what raw)")
            what = "raw"
    if what == "raw":
        return [FORMATS[fmt].writer("raw")(run, out)], notes
    paths, more = write_data(data, fmt, what, out, run_record(run), request, str(run_dir))
    return paths, notes + more


def write_data(data: ReducedData, fmt: str, what: str, out: Path, record: Mapping[str, Any],
               request: ExportRequest, source: str = "") -> tuple[list[Path], list[str]]:
    """Write reduced data (`what` reduced) or its fit (`what` model) as `fmt` by the format's
    writer (calibration.exports.writers); (paths, notes). `record`: the run's record
    (gonio.record.run_record), which every file carries."""
    return FORMATS[fmt].writer(what)(data, out, record, request, source)
