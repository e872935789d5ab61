"""The files of one export: reduced data (or a run's raw readings) and a fit, written as the
format asks (calibration.exports.write's defaults and choices)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from calibration.exports.astm import astm_tables, side_paths, write_astm
from calibration.exports.cf import write_reduced_netcdf
from calibration.exports.measured import fact_lines, write_reduced_csv
from calibration.exports.model import (
    astm_model_tables,
    fit_for_export,
    fit_notes,
    measured_zemax_files,
    mitsuba_file,
    zemax_files,
)
from calibration.exports.request import ExportRequest
from calibration.reduced import ReducedData
from gonio.errors import GonioError
from gonio.record import record_lines, run_record


def write_run(run_dir: str | Path, fmt: str, what: str, out: Path, request: ExportRequest,
              fallback: bool) -> tuple[list[Path], list[str]]:
    """Reduce the run (unless `what` is raw) and write it; with `fallback`, a run that cannot
    be reduced is written raw, with a note saying why."""
    from calibration.exports.bluesky import write_jsonl
    from calibration.exports.raw import write_csv, write_netcdf
    from calibration.pipeline import reduce_run
    from gonio.store import open_run

    run = open_run(run_dir)
    notes: list[str] = []
    if what != "raw":
        try:
            data = reduce_run(run, request.calibration, request.shot_noise_w,
                              request.subtract_signature)
        except GonioError as exc:
            if not fallback:
                raise
            notes.append(f"export: the run cannot be reduced ({exc}); wrote its raw readings "
                         "(--what raw)")
            what = "raw"
    if what == "raw":
        writer = {"csv": write_csv, "netcdf": write_netcdf, "bluesky": write_jsonl}[fmt]
        return [writer(run, out)], notes
    paths, more = write_data(data, fmt, what, out, run_record(run), request, str(run_dir))
    return paths, notes + more


def write_data(data: ReducedData, fmt: str, what: str, out: Path, record: Mapping[str, Any],
               request: ExportRequest, source: str = "") -> tuple[list[Path], list[str]]:
    """Write reduced data (`what` reduced) or its fit (`what` model) as `fmt`; (paths,
    notes). `record`: the run's record (gonio.record.run_record), which every file carries;
    the text files then the reduction's facts (measured.fact_lines), with the index their
    tables were made with (the fit's, where a fit made them), so `--import` reads it again."""
    lines = record_lines(record)
    if what == "reduced" and fmt == "csv":
        return [write_reduced_csv(data, out, lines)], []
    if what == "reduced" and fmt == "netcdf":
        return [write_reduced_netcdf(data, record, out)], []
    if what == "reduced" and fmt == "astm":
        return _astm_files(astm_tables(data, [*lines, *fact_lines(data)]), out), []
    result, warnings = fit_for_export(data, request.fit_options, request.fit_file,
                                      request.force)
    lines = [*lines, *fact_lines(data, result.eta), *warnings]
    if fmt == "mitsuba":
        return [mitsuba_file(result, out, source, lines)], warnings
    if fmt == "astm":
        return _astm_files(astm_model_tables(data, result, fit_notes(result, source, lines)),
                           out), warnings
    if what == "model":
        return zemax_files(data, result, out, source, lines), warnings
    return measured_zemax_files(data, result, out, source, lines), warnings


def _astm_files(tables: list, out: Path) -> list[Path]:
    """One ASTM file per side's table, named by side_paths."""
    paths = side_paths(out, [t.data_type for t in tables])
    return [write_astm(t, p) for t, p in zip(tables, paths, strict=True)]
