"""NetCDF exports that follow the CF conventions (CF-1.8): a run's raw readings along a
`reading` dimension and its reduced BSDF along a `point` dimension, each variable with `units`
and `long_name`, text fields as flag variables (`flag_values` or `flag_masks` with
`flag_meanings`), times in seconds since the run's start, and the global `title`, `history`,
`source`, `Conventions`; the run's record (gonio.record.run_record) as further attributes.
The reduced BSDF's uncertainty and error correlation follow calibration.exports.cf_uncertainty.
`read_reduced_netcdf` reads the reduced file back."""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from calibration.exports.cf_uncertainty import (
    CORRELATION,
    mark_interval,
    read_shared_rel,
    write_error_structure,
)
from calibration.exports.measured import columns, coverage_k, meta_facts, unit_vectors
from calibration.formats.limits import (
    MAX_COLUMNS,
    MAX_POINTS,
    MeasuredFile,
    check_count,
    measured_file,
)
from calibration.formats.netcdf_classic import check_classic_header
from calibration.reduced import ReducedData
from calibration.values import CalibrationError
from gonio.errors import GonioError
from gonio.store import READING_DTYPE

CONVENTIONS = "CF-1.8"
CF_GLOBALS = ("Conventions", "title", "history", "source", "comment")  # _globals writes them
FRAME = "angles in the sample (BSDF) frame of gonio's docs/architecture.md, degrees"
RAW_LONG_NAMES = {
    "index": "reading index in the run", "kind": "kind of reading",
    "side": "side of the sample the detector faces", "repeat": "repeat of the plan point",
    "point": "plan point index", "sample_deg": "sample stage angle",
    "arm_deg": "detector arm angle", "azimuth_deg": "azimuth stage angle",
    "elevation_deg": "elevation stage angle", "theta_i_deg": "incidence polar angle",
    "phi_i_deg": "incidence azimuth", "theta_o_deg": "outgoing polar angle",
    "phi_o_deg": "outgoing azimuth", "plan_theta_i_deg": "planned incidence polar angle",
    "plan_theta_o_deg": "planned outgoing polar angle",
    "plan_phi_o_deg": "planned outgoing azimuth", "power_w": "detector power",
    "range_w": "detector range (full scale)", "saturated": "detector saturated",
    "t_s": "time of the reading", "flags": "flags the engine recorded on the reading",
}
REDUCED_LONG_NAMES = {
    "theta_i_deg": "incidence polar angle from the sample normal",
    "phi_i_deg": "incidence azimuth from the sample frame's +x",
    "theta_o_deg": "outgoing polar angle from the sample normal (above 90 for transmission)",
    "phi_o_deg": "outgoing azimuth from the sample frame's +x",
    "bsdf": "bidirectional scattering distribution function (not cosine-corrected)",
    "sigma": "standard uncertainty of bsdf (GUM u)",
    "U": "expanded uncertainty of bsdf (GUM U = k u)",
}
# Reduced variable names in the file: the CSV's column names without their unit suffix.
REDUCED_NAMES = {"theta_i_deg": "theta_i", "phi_i_deg": "phi_i", "theta_o_deg": "theta_o",
                 "phi_o_deg": "phi_o", "bsdf": "bsdf", "sigma": "bsdf_standard_uncertainty",
                 "U": "bsdf_expanded_uncertainty"}


def _netcdf4() -> Any:
    try:
        import netCDF4
    except ImportError:
        raise GonioError("NetCDF export needs the netCDF4 package "
                         "(pip install 'gonio[netcdf]')") from None
    return netCDF4


def _words(values: np.ndarray) -> list[str]:
    """Distinct non-empty words of comma- or semicolon-separated text values, sorted."""
    return sorted({w for v in values for w in re.split(r"[,;]", str(v)) if w})


def _flag_meaning(word: str) -> str:
    """A word as CF flag_meanings allow (letters, digits, _ . + - @)."""
    return re.sub(r"[^A-Za-z0-9_.+\-@]", "_", word)


def _enumerated(ds: Any, name: str, values: np.ndarray, dim: str, long_name: str,
                words: list[str] | None = None) -> None:
    """A text field with one value per entry as a byte flag variable (flag_values); `words`:
    its vocabulary (default: the values present)."""
    words = words or sorted({str(v) for v in values})
    code = {w: k for k, w in enumerate(words)}
    var = ds.createVariable(name, "i1", (dim,))
    var[:] = np.array([code[str(v)] for v in values], dtype=np.int8)
    var.long_name = long_name
    var.flag_values = np.arange(len(words), dtype=np.int8)
    var.flag_meanings = " ".join(_flag_meaning(w or "none") for w in words)


def _flag_masks(ds: Any, name: str, values: np.ndarray, dim: str, long_name: str) -> None:
    """A field of flag words (comma- or semicolon-separated) as a bit-mask flag variable;
    without any word, a flag variable whose one value 0 means none."""
    words = _words(values)
    bits = {w: 1 << k for k, w in enumerate(words)}
    var = ds.createVariable(name, "i4", (dim,))
    var[:] = np.array([sum(bits[w] for w in set(re.split(r"[,;]", str(v))) if w)
                       for v in values], dtype=np.int32)
    var.long_name = long_name
    if words:
        var.flag_masks = np.array(list(bits.values()), dtype=np.int32)
        var.flag_meanings = " ".join(_flag_meaning(w) for w in words)
    else:
        var.flag_values = np.array([0], dtype=np.int32)
        var.flag_meanings = "none"


def _globals(ds: Any, title: str, record: Mapping[str, Any], extra: Mapping[str, Any]) -> None:
    """CF global attributes, then the record's and `extra`'s (numbers and text as they are,
    the rest as JSON)."""
    for source in (record, extra):
        for key, value in source.items():
            if value is None:
                continue
            ds.setncattr(key, value if isinstance(value, (str, int, float))
                         and not isinstance(value, bool) else json.dumps(value))
    now = datetime.now(UTC).isoformat(timespec="seconds")
    emulated = "the emulated bench" if record.get("emulated") else (
        f"instrument {record.get('instrument') or 'unnamed'}")
    ds.Conventions = CONVENTIONS
    ds.title = title
    ds.history = f"{now} gonio export of run {record.get('run')}"
    ds.source = f"gonio gonioreflectometer, {emulated}"
    ds.comment = FRAME


READING_UNITS = {"_deg": "degree", "_w": "W", "t_s": "s"}  # by the reading field's name ending


def reading_unit(name: str) -> str:
    """The unit of a reading field (gonio.store.READING_DTYPE), "" for a dimensionless one."""
    return next((u for suffix, u in READING_UNITS.items() if name.endswith(suffix)), "")


def epoch_units(t0_epoch: float | None) -> str:
    """CF time units of seconds since the run's clock origin (meta.json `t0_epoch`, the instant
    every reading's `t_s` counts from), in UTC."""
    if t0_epoch is None:
        return "s"
    start = datetime.fromtimestamp(float(t0_epoch), tz=UTC)
    return f"seconds since {start.strftime('%Y-%m-%d %H:%M:%S.%f')}"


VIRTUAL_CLOCK = "run time on the emulated bench's virtual clock, not wall-clock time"


def _run_time(var: Any, t0_epoch: float | None, virtual_clock: bool) -> None:
    """`t_s`'s attributes: a CF time since `t0_epoch`, or plain seconds of run time (no
    `t0_epoch`, or counted on the emulated bench's virtual clock, which says so)."""
    if virtual_clock:
        var.units = "s"
        var.comment = VIRTUAL_CLOCK
        return
    var.standard_name = "time"
    var.units = epoch_units(t0_epoch)
    var.calendar = "standard"


def _stored_dtype(col: np.ndarray) -> np.dtype:
    """The type a numeric field is written as: int32 for integers that fit (CF's strict
    checkers take 64-bit integers as outside the classic data model), else its own."""
    info = np.iinfo(np.int32)
    if col.dtype.kind == "i" and (len(col) == 0 or info.min <= col.min() <= col.max() <= info.max):
        return np.dtype(np.int32)
    return col.dtype


def write_raw_netcdf(readings: np.ndarray, record: Mapping[str, Any], out: Path,
                     t0_epoch: float | None = None, virtual_clock: bool = False) -> Path:
    """A run's readings (READING_DTYPE) as CF-1.8 NetCDF4, dimension `reading`; `t_s` as time
    since `t0_epoch` (without it, plain seconds; with `virtual_clock`, a run counted on the
    emulated bench's virtual clock, plain seconds of run time)."""
    netCDF4 = _netcdf4()
    with netCDF4.Dataset(out, "w", format="NETCDF4") as ds:
        ds.createDimension("reading", len(readings))
        for name in READING_DTYPE.names:
            col, long_name = readings[name], RAW_LONG_NAMES[name]
            if name == "flags":
                _flag_masks(ds, name, col, "reading", long_name)
            elif col.dtype.kind == "O":
                _enumerated(ds, name, col, "reading", long_name)
            elif col.dtype.kind == "b":
                var = ds.createVariable(name, "i1", ("reading",))
                var[:] = col.astype(np.int8)
                var.long_name = long_name
                var.flag_values = np.array([0, 1], dtype=np.int8)
                var.flag_meanings = "no yes"
            else:
                var = ds.createVariable(name, _stored_dtype(col), ("reading",))
                var[:] = col
                var.long_name = long_name
                if name == "t_s":
                    _run_time(var, t0_epoch, virtual_clock)
                else:
                    var.units = reading_unit(name) or "1"
        _globals(ds, f"gonio run {record.get('run')}: raw readings", record, {})
    return out


def write_reduced_netcdf(data: ReducedData, record: Mapping[str, Any], out: Path) -> Path:
    """Reduced BSDF as CF-1.8 NetCDF4, dimension `point` (see the module docstring)."""
    netCDF4 = _netcdf4()
    cols = columns(data)
    with netCDF4.Dataset(out, "w", format="NETCDF4") as ds:
        ds.createDimension("point", len(data.bsdf))
        for column, name in REDUCED_NAMES.items():
            var = ds.createVariable(name, "f8", ("point",))
            var[:] = cols[column]
            var.long_name = REDUCED_LONG_NAMES[column]
            var.units = "degree" if column.endswith("_deg") else "sr-1"
        mark_interval(ds[REDUCED_NAMES["sigma"]], 1.0)
        mark_interval(ds[REDUCED_NAMES["U"]], coverage_k(data))
        components = [c for c in cols if c.startswith("u_")]
        for name in components:
            var = ds.createVariable(name, "f8", ("point",))
            var[:] = cols[name]
            var.long_name = f"standard uncertainty component {name[2:]} of bsdf"
            var.units = "sr-1"
        _enumerated(ds, "valid", np.where(data.valid, "valid", "invalid"), "point",
                    "whether fits and plots use the point", ["invalid", "valid"])
        _enumerated(ds, "side", np.where(data.transmission, "transmission", "reflection"),
                    "point", "side of the sample the outgoing direction is on",
                    ["reflection", "transmission"])
        _flag_masks(ds, "flags", data.flags, "point", "why a point is suspect")
        wavelength = ds.createVariable("wavelength", "f8", ())
        wavelength.long_name = "wavelength of the source"
        wavelength.standard_name = "radiation_wavelength"
        wavelength.units = "nm"
        wavelength.assignValue(data.meta.get("wavelength_nm") or math.nan)
        solid_angle = ds.createVariable("receiver_solid_angle", "f8", ())
        solid_angle.long_name = "solid angle of the receiver aperture"
        solid_angle.units = "sr"
        solid_angle.assignValue(data.meta.get("aperture_sr") or math.nan)
        bsdf = ds["bsdf"]
        bsdf.coordinates = "theta_i phi_i theta_o phi_o wavelength"
        intervals = [REDUCED_NAMES["sigma"], REDUCED_NAMES["U"]]
        bsdf.uncertainty_variables = " ".join(intervals)
        structure = write_error_structure(ds, data, "bsdf")
        bsdf.ancillary_variables = " ".join([*intervals, *components, *structure, "valid",
                                             "side", "flags", "receiver_solid_angle"])
        _globals(ds, f"gonio run {record.get('run')}: reduced BSDF", record,
                 {f"gonio_{key}": value for key, value in meta_facts(data).items()})
    return out


def _attribute(value: Any) -> Any:
    """A global attribute as written: JSON text back to its value, the rest as it is."""
    if isinstance(value, str):
        try:
            return json.loads(value)
        except ValueError:
            return value
    return value.item() if isinstance(value, np.generic) else value


#: What netCDF4 and numpy raise on a damaged file's contents (an undecodable name, a failed
#: read, a variable of the wrong shape or without its attributes).
DAMAGED = (RuntimeError, ValueError, TypeError, IndexError, KeyError, AttributeError)


def read_reduced_netcdf(source: str | Path | MeasuredFile) -> ReducedData:
    """ReducedData of a file write_reduced_netcdf wrote (meta: its gonio_* attributes, and the
    run's record as meta["record"]: the other attributes but CF_GLOBALS); a damaged file is one
    CalibrationError naming it. The library reads the bytes that were checked, from memory
    (limits.measured_file: read once, within the limits)."""
    netCDF4 = _netcdf4()
    file = measured_file(source)
    path = file.path
    if file.data.startswith(b"CDF"):  # classic: its header walked first, which the library trusts
        check_classic_header(path, file.data)
    try:
        ds = netCDF4.Dataset(str(path), memory=file.data)
    except (OSError, UnicodeDecodeError) as exc:
        raise CalibrationError(f"{path}: not a NetCDF file ({exc})") from None
    try:
        with ds:
            return _reduced_of(ds, path)
    except DAMAGED as exc:
        raise CalibrationError(f"{path}: damaged NetCDF file ({exc})") from None


def _reduced_of(ds: Any, path: Path) -> ReducedData:
    """read_reduced_netcdf of the open dataset."""
    missing = [n for n in REDUCED_NAMES.values() if n not in ds.variables]
    if missing:
        raise CalibrationError(f"{path}: not a gonio reduced NetCDF file: no variable "
                               f"{', '.join(missing)}")
    _check_declared(ds, path)
    get = {n: np.asarray(ds[n][:], dtype=np.float64) for n in REDUCED_NAMES.values()}
    meta = {key[len("gonio_"):]: _attribute(ds.getncattr(key)) for key in ds.ncattrs()
            if key.startswith("gonio_")}
    record = {key: _attribute(ds.getncattr(key)) for key in ds.ncattrs()
              if not key.startswith("gonio_") and key not in CF_GLOBALS}
    if record:
        meta["record"] = record
    wavelength = float(ds["wavelength"][...]) if "wavelength" in ds.variables else math.nan
    if math.isfinite(wavelength):
        meta["wavelength_nm"] = wavelength
    components = {n[2:]: np.asarray(ds[n][:], dtype=np.float64) for n in ds.variables
                  if n.startswith("u_")}
    shared_rel = read_shared_rel(ds, get["bsdf"])
    valid = _decoded(ds, "valid", "valid") if "valid" in ds.variables else None
    flags = _flag_words(ds["flags"]) if "flags" in ds.variables else None
    wi = unit_vectors(get["theta_i"], get["phi_i"])
    wo = unit_vectors(get["theta_o"], get["phi_o"])
    n = len(wi)
    return ReducedData(wi, wo, get["bsdf"], get["bsdf_standard_uncertainty"],
                       np.ones(n, bool) if valid is None else valid, wo[:, 2] < 0, meta,
                       shared_rel, flags=flags, components=components)


#: The most points whose shared-error correlation matrix an import reads (N^2 float64 values
#: and their eigendecomposition: 128 MiB and seconds at this size).
MAX_CORRELATED_POINTS = 4096


def _check_declared(ds: Any, path: Path) -> None:
    """Refuse, before any is read, variables that declare more than an import holds
    (calibration.formats.limits)."""
    read = [var for name, var in ds.variables.items()
            if name in (*REDUCED_NAMES.values(), "wavelength", "valid", "flags")
            or name.startswith("u_")]
    check_count(path, len(read), "variables", MAX_COLUMNS)
    for var in read:
        check_count(path, var.size, f"values of variable {var.name}", MAX_POINTS)
    if CORRELATION in ds.variables:  # N x N values, and an eigendecomposition of them
        points = ds[REDUCED_NAMES["bsdf"]].size
        if ds[CORRELATION].shape != (points, points):
            raise CalibrationError(f"{path}: variable {CORRELATION} has shape "
                                   f"{ds[CORRELATION].shape}, not ({points}, {points})")
        check_count(path, points, f"points in variable {CORRELATION}", MAX_CORRELATED_POINTS)


def _decoded(ds: Any, name: str, meaning: str) -> np.ndarray:
    """True where an enumerated flag variable holds `meaning`."""
    var = ds[name]
    meanings = str(var.flag_meanings).split()
    code = int(np.atleast_1d(var.flag_values)[meanings.index(meaning)])
    return np.asarray(var[:]) == code


def _flag_words(var: Any) -> np.ndarray:
    """Comma-separated flag words of a bit-mask flag variable."""
    values = np.asarray(var[:])
    if "flag_masks" not in var.ncattrs():
        return np.full(len(values), "")
    words = str(var.flag_meanings).split()
    masks = np.atleast_1d(var.flag_masks)
    return np.array([",".join(w for w, m in zip(words, masks, strict=True) if v & m)
                     for v in values])
