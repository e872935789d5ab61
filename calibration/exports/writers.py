"""The writer of reduced data and of its fit for each format and `--what`, as
calibration.formats names them: each takes (ReducedData, out path, the run's record,
ExportRequest, source) and returns (files written, notes). The text files carry the record then
the reduction's facts (measured.fact_lines), with the index their tables were made with (the
fit's, where a fit made them), so `--import` reads it again."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from calibration.exports.astm import AstmTable, astm_tables, side_paths, write_astm
from calibration.exports.bird import write_bird
from calibration.exports.bird_supplement import supplemented
from calibration.exports.cf import write_reduced_netcdf
from calibration.exports.family_fit import check_family, family_fit, family_of
from calibration.exports.measured import fact_lines, shared_error_lines, write_reduced_csv
from calibration.exports.model import (
    astm_model_tables,
    fit_for_export,
    fit_notes,
    measured_zemax_files,
    mitsuba_files,
    zemax_files,
)
from calibration.exports.request import ExportRequest
from calibration.fit import FitResult
from calibration.reduced import ReducedData
from gonio.record import record_lines

Written = tuple[list[Path], list[str]]
DataWriter = Callable[[ReducedData, Path, Mapping[str, Any], ExportRequest, str], Written]


def reduced_csv(data: ReducedData, out: Path, record: Mapping[str, Any],
                request: ExportRequest, source: str = "") -> Written:
    """The reduced data as gonio's CSV (measured.write_reduced_csv)."""
    return [write_reduced_csv(data, out, record_lines(record))], []


def reduced_netcdf(data: ReducedData, out: Path, record: Mapping[str, Any],
                   request: ExportRequest, source: str = "") -> Written:
    """The reduced data as CF-1.8 NetCDF (cf.write_reduced_netcdf)."""
    return [write_reduced_netcdf(data, record, out)], []


def reduced_bird(data: ReducedData, out: Path, record: Mapping[str, Any],
                 request: ExportRequest, source: str = "") -> Written:
    """The reduced data's reflection points as a BiRD universal BRDF file (bird.write_bird;
    its notes say what it leaves out), with what the request's provenance file gives where
    the record lacks it (bird_supplement.supplemented)."""
    if request.provenance is not None:
        record = supplemented(record, request.provenance)
    path, notes = write_bird(data, out, record)
    return [path], notes


def reduced_astm(data: ReducedData, out: Path, record: Mapping[str, Any],
                 request: ExportRequest, source: str = "") -> Written:
    """The reduced data as ASTM E1392, one file per side (the BTDF first); each header states
    its points' shared errors (measured.shared_error_lines) after the record and the facts."""
    lines = [*record_lines(record), *fact_lines(data)]
    good = data.subset(data.valid)
    sides = [good.subset(good.transmission == btdf) for btdf in (True, False)]
    tables = [t for side in sides for t in astm_tables(side, [*lines, *shared_error_lines(side)])]
    return _astm_files(tables, out), []


def _with_fit(write: Callable[[ReducedData, FitResult, Path, str, list[str]], list[Path]]
              ) -> DataWriter:
    """A writer that takes the fit (--fit FIT.json, or fitted; model.fit_for_export, which
    refuses a fit that does not describe the data) and hands `write` the data, the fit, the
    out path, the source and the file's lines (the record, the facts, the fit's warnings)."""
    def write_fitted(data: ReducedData, out: Path, record: Mapping[str, Any],
                     request: ExportRequest, source: str = "") -> Written:
        result, warnings, lines = _fitted(data, record, request)
        return write(data, result, out, source, lines), warnings
    return write_fitted


def _fitted(data: ReducedData, record: Mapping[str, Any], request: ExportRequest
            ) -> tuple[FitResult, list[str], list[str]]:
    """The fit to export (model.fit_for_export), its warnings and the file's lines (the record,
    the facts, the warnings)."""
    result, warnings = fit_for_export(data, request.fit_options, request.fit_file, request.force)
    eta = result.eta if family_fit(result) is None else None  # a family's tables: the data's index
    return result, warnings, [*record_lines(record), *fact_lines(data, eta), *warnings]


def _astm_files(tables: Sequence[AstmTable], out: Path) -> list[Path]:
    """One ASTM file per side's table, named by side_paths."""
    paths = side_paths(out, [t.data_type for t in tables])
    return [write_astm(t, p) for t, p in zip(tables, paths, strict=True)]


def _model_astm_files(data: ReducedData, result: FitResult, out: Path, source: str,
                      lines: list[str]) -> list[Path]:
    """ASTM E1392 of the fitted model on a grid, one file per side (model.astm_model_tables)."""
    return _astm_files(astm_model_tables(data, result, fit_notes(result, source, lines)), out)


def model_mitsuba(data: ReducedData, out: Path, record: Mapping[str, Any],
                  request: ExportRequest, source: str = "") -> Written:
    """The Mitsuba 3 material of the fitted model (model.mitsuba_files; single-scattering only
    with request.single_scattering, the line saying what it drops among the notes)."""
    result, warnings, lines = _fitted(data, record, request)
    paths, said = mitsuba_files(result, out, source, lines, request.single_scattering)
    return paths, [*warnings, *said]


def model_abg(data: ReducedData, out: Path, record: Mapping[str, Any],
              request: ExportRequest, source: str = "") -> Written:
    """An ABg fit as an entry of Zemax OpticStudio's ABg scatter data catalog (zemax_abg),
    named after the file, at the data's wavelength; a fit of another family is refused, naming
    the formats that take it (family_fit.check_family)."""
    from calibration.exports.zemax_abg import abg_entry, tis_notes, write_abg

    result, warnings, lines = _fitted(data, record, request)
    family = family_fit(result)
    check_family("abg", family_of(result))
    tis_line, said = tis_notes(family)
    entry = abg_entry(family, out.stem, data.meta.get("wavelength_nm"))
    notes = [*fit_notes(result, source, lines), *tis_line, *said]
    if entry.wave_um == 0.0:
        notes.append("the data give no wavelength: Wave 0, so OpticStudio does not scale A "
                     "and B with wavelength")
    return [write_abg(entry, out, notes)], [*warnings, *said]


#: Zemax of the data, with the model filling where there is none (model.measured_zemax_files).
reduced_zemax = _with_fit(measured_zemax_files)
#: Zemax of the fitted model (model.zemax_files).
model_zemax = _with_fit(zemax_files)
model_astm = _with_fit(_model_astm_files)
