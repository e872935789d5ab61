"""Measured BSDF files that gonio did not make, read into the ReducedData that `fit` and
`reduce` use: ASTM E1392 (`.astm`), Zemax tabular BSDF (`.bsdf`, `.zmx`, `.txt` with its
keywords), gonio's reduced NetCDF (`.nc`) and CSV, or a plain CSV with named columns
(theta_i, phi_i, theta_o, phi_o in degrees, with or without `_deg`, theta_o above 90 for
transmission; bsdf; optional sigma and wavelength_nm). calibration.formats names the reader
of each format and tells which format a file is.

Uncertainties come from the file where it has them (CSV `sigma`, NetCDF); otherwise from a
stated assumption (`sigma_relative`: u = that fraction of |bsdf|, put into meta["noise_model"]),
and the index from the file (the `# eta: ...` line of gonio's CSV, ASTM and Zemax exports, else
their record's sample block; the NetCDF's attributes) or from `eta`. Every input a file lacks
and no option gives is named in one error (MissingInputs). The run's record that gonio's files
carry (`# key: JSON` lines before the facts' `quantity`; the NetCDF's record attributes) goes
into meta["record"], so that a file written from the import carries it on.
"""

from __future__ import annotations

import csv
import itertools
import json
import math
from pathlib import Path

import numpy as np

from calibration.exports.measured import ANGLE_COLUMNS, META_KEYS, unit_vectors
from calibration.formats import format_to_read
from calibration.formats.file_format import ImportOptions
from calibration.reduced import ReducedData
from calibration.values import CalibrationError

# the column names of reduced.csv as `gonio reduce` wrote it before it used write_reduced_csv
ALIASES = {"bsdf_per_sr": "bsdf", "sigma_per_sr": "sigma"}


class MissingInputs(CalibrationError):
    """Inputs a file lacks and no option gives, all of them in one error."""

    def __init__(self, path: Path, problems: list[str]) -> None:
        self.path, self.problems = path, problems
        listed = (problems[0] if len(problems) == 1 else f"{len(problems)} inputs missing: "
                  + "; ".join(f"({n}) {p}" for n, p in enumerate(problems, 1)))
        super().__init__(f"{path}: {listed}")


def read_measured(path: str | Path, options: ImportOptions | None = None) -> ReducedData:
    """The file's measurements as ReducedData, read as the format calibration.formats.
    format_to_read tells (its magic, its suffix, or for a text file of another suffix its first
    keyword); a MissingInputs error names every input the file lacks."""
    path = Path(path)
    options = options or ImportOptions()
    if not path.is_file():
        raise CalibrationError(f"{path}: no such file")
    data = format_to_read(path).read(path, options)
    data.meta["imported_from"] = str(path)
    return data


def from_netcdf(path: Path, options: ImportOptions) -> ReducedData:
    """gonio's reduced NetCDF file (calibration.exports.cf), with the uncertainties it states."""
    from calibration.exports.cf import read_reduced_netcdf

    data = read_reduced_netcdf(path)
    data.meta["eta"] = _inputs(path, options, data.meta, "the NetCDF file", True)
    data.meta.setdefault("assumption", "uncertainties as the file states them")
    return data


def _inputs(path: Path, options: ImportOptions, meta: dict, what: str,
            has_sigma: bool) -> float:
    """The index to use (the option's, else the file's); one MissingInputs error naming each
    input the file lacks that no option gives (or an option's value out of range)."""
    problems = []
    relative = options.sigma_relative
    if not has_sigma and relative is None:
        problems.append(f"{what} has no uncertainties, which the fit needs: give "
                        "--sigma-relative FRACTION to assume u = FRACTION * |bsdf|")
    elif not has_sigma and not 0.0 < relative < 10.0:
        problems.append(f"--sigma-relative must be in (0, 10), got {relative!r}")
    eta = options.eta if options.eta is not None else meta.get("eta")
    if eta is None:
        problems.append("the file gives no refractive index (eta), which the fit needs for a "
                        "dielectric: give --eta")
    elif not (isinstance(eta, (int, float)) and math.isfinite(eta) and eta > 0):
        problems.append(f"eta must be a number > 0, got {eta!r}")
    if problems:
        raise MissingInputs(path, problems)
    return float(eta)


def _assumed_sigma(bsdf: np.ndarray, relative: float) -> tuple[np.ndarray, str]:
    """(sigma, the assumption stated) for a file without uncertainties (_inputs checked
    `relative`)."""
    return relative * np.abs(bsdf), (
        f"assumed: u = {relative:g} * |bsdf| (the file states no uncertainties; "
        "--sigma-relative); values of 0 get no u from it and are left out (flag 'zero')")


def _reduced(path: Path, wi: np.ndarray, wo: np.ndarray, bsdf: np.ndarray,
             sigma: np.ndarray | None, transmission: np.ndarray, meta: dict,
             options: ImportOptions) -> ReducedData:
    """ReducedData of imported samples (meta["eta"] set by _inputs); the noise model says
    where sigma comes from."""
    if sigma is None:
        sigma, meta["noise_model"] = _assumed_sigma(bsdf, options.sigma_relative)
        meta["assumption"] = meta["noise_model"]
    else:
        meta.setdefault("noise_model", f"as stated in {path.name}")
    finite = np.isfinite(bsdf) & np.isfinite(sigma) & (sigma > 0)
    valid = meta.pop("valid", np.ones(len(bsdf), bool)) & finite
    flags = meta.pop("flags", None)
    zero = np.isfinite(bsdf) & (bsdf == 0) & ~(sigma > 0)
    if zero.any():  # a relative u of 0 would weigh the point infinitely: it is left out
        flags = np.array([""] * len(bsdf), dtype=object) if flags is None else flags.copy()
        flags[zero] = ["zero" if not f else f"{f},zero" for f in flags[zero]]
    components = meta.pop("components", {})
    return ReducedData(wi, wo, bsdf, sigma, valid, transmission, meta, flags=flags,
                       components=components)


def _header(comments: list[str]) -> tuple[dict, dict]:
    """(record, facts) of the `key: JSON` comment lines of a gonio file (comment text without
    its `#`; other lines are left out): the record is what comes before the facts' first line,
    `quantity` (measured.fact_lines); a file without one gives every entry as a fact and those
    that are not META_KEYS as its record."""
    entries = []
    for line in comments:
        key, sep, value = line.strip().partition(": ")
        if sep:
            try:
                entries.append((key, json.loads(value)))
            except ValueError:
                continue
    keys = [key for key, _ in entries]
    if "quantity" in keys:
        start = keys.index("quantity")
        return dict(entries[:start]), dict(entries[start:])
    return {k: v for k, v in entries if k not in META_KEYS}, dict(entries)


def _facts(path: Path, options: ImportOptions, comments: list[str], what: str,
           has_sigma: bool) -> dict:
    """The meta of a text file's comments: its facts (META_KEYS, from the record where the
    facts lack one, e.g. its sample block), the index (the option's, else the `eta` fact, else
    the sample block's: _inputs) and meta["record"]."""
    record, facts = _header(comments)
    meta = {k: v for k, v in {**record, **facts}.items() if k in META_KEYS}
    sample = record.get("sample")
    if "eta" not in meta and isinstance(sample, dict) and "eta" in sample:
        meta["eta"] = sample["eta"]
    meta["eta"] = _inputs(path, options, meta, what, has_sigma)
    if record:
        meta["record"] = record
    return meta


def from_csv(path: Path, options: ImportOptions) -> ReducedData:
    """A plain or gonio CSV (see the module docstring)."""
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise CalibrationError(f"{path}: not a readable text file ({exc})") from None
    lines = text.splitlines()
    rows = list(csv.reader(ln for ln in lines if ln.strip() and not ln.startswith("#")))
    if len(rows) < 2:
        raise CalibrationError(f"{path}: no data rows under a header of column names")
    names = [ALIASES.get(n.strip(), n.strip()) for n in rows[0]]
    index = {}
    for k, name in enumerate(names):
        index.setdefault(name, k)
        if name.endswith("_deg"):
            index.setdefault(name[:-4], k)
    needed = [a[:-4] for a in ANGLE_COLUMNS] + ["bsdf"]
    missing = [n for n in needed if n not in index]
    if missing:
        raise CalibrationError(f"{path}: no column {', '.join(missing)} (columns: theta_i_deg, "
                               "phi_i_deg, theta_o_deg, phi_o_deg, bsdf, optional sigma, "
                               "wavelength_nm)")
    body = rows[1:]
    meta = _facts(path, options, [ln[1:] for ln in lines if ln.startswith("#")], "the CSV",
                  "sigma" in index)

    def column(name: str) -> np.ndarray:
        k = index[name]
        try:
            return np.array([float(r[k]) if r[k].strip() else math.nan for r in body])
        except (ValueError, IndexError):
            bad = next(n for n, r in enumerate(body)
                       if len(r) <= k or not _is_number(r[k]))
            raise CalibrationError(f"{path}: data row {bad + 1}: column {name} is not a "
                                   "number") from None

    ti, pi, to, po, bsdf = (column(n) for n in needed)
    sigma = column("sigma") if "sigma" in index else None
    if "wavelength_nm" in index:
        wavelengths = np.unique(column("wavelength_nm"))
        if len(wavelengths) == 1 and np.isfinite(wavelengths[0]):
            meta["wavelength_nm"] = float(wavelengths[0])
    if "valid" in index:
        meta["valid"] = column("valid") != 0
    if "flags" in index:
        meta["flags"] = np.array([r[index["flags"]].replace(";", ",") for r in body])
    meta["components"] = {n[2:]: column(n) for n in names if n.startswith("u_")}
    wi, wo = unit_vectors(ti, pi), unit_vectors(to, po)
    return _reduced(path, wi, wo, bsdf, sigma, wo[:, 2] < 0, meta, options)


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def from_astm(path: Path, options: ImportOptions) -> ReducedData:
    """An ASTM E1392 file: its first value column (one wavelength)."""
    from calibration.exports.astm import directions, read_astm

    table = read_astm(path)
    if table.values.shape[1] != 1:
        raise CalibrationError(f"{path}: {table.values.shape[1]} value columns (one per "
                               "wavelength); the fit takes one wavelength: split the file")
    meta = _facts(path, options, table.comments, "an ASTM E1392 file", False)
    wi, wo, transmission = directions(table)
    if math.isfinite(table.wavelengths_nm[0]):
        meta["wavelength_nm"] = table.wavelengths_nm[0]
    return _reduced(path, wi, wo, table.values[:, 0], None, transmission, meta, options)


def from_zemax(path: Path, options: ImportOptions) -> ReducedData:
    """A Zemax tabular BSDF file: every grid value on its side's hemisphere (the file does
    not say which are measured, so the fit takes all of them), at its incidence angles
    (BTDF: recovered from the direct-transmission angle with `eta`)."""
    from calibration.exports.zemax import on_side, read_zemax, scatter_directions, turned

    table = read_zemax(path)
    meta = _facts(path, options, table.comments, "a Zemax tabular BSDF file", False)
    eta = meta["eta"]
    wi, wo, bsdf = [], [], []
    for (r, rotation), (a, angle) in itertools.product(enumerate(table.sample_rotation_deg),
                                                       enumerate(table.angle_deg)):
        if r and angle == 0.0:  # normal incidence: every rotation holds the same points
            continue
        theta_i = (angle if table.scatter_type == "BRDF" else
                   math.degrees(math.asin(min(1.0, eta * math.sin(math.radians(angle))))))
        directions = scatter_directions(angle, table.scatter_type, table.azimuth_deg,
                                        table.radial_deg)
        keep = on_side(directions, table.scatter_type)
        keep &= np.abs(directions[..., 2]) > 1e-9
        keep[1:, table.radial_deg == 0.0] = False  # the specular direction, once
        keep[table.azimuth_deg >= 360.0] = False  # a closing row repeats azimuth 0
        if table.symmetry == "PlaneSymmetrical":
            inside = (table.azimuth_deg > 0) & (table.azimuth_deg < 180)
            mirrored = directions[inside] * np.array([1.0, -1.0, 1.0])
            directions = np.concatenate([directions, mirrored])
            values = np.concatenate([table.data[r, a], table.data[r, a][inside]])
            keep = np.concatenate([keep, keep[inside]])
        else:
            values = table.data[r, a]
        ti = math.radians(theta_i)
        wo.append(turned(directions[keep], -rotation))  # the sample turned by `rotation`
        bsdf.append(values[keep])
        wi.append(np.broadcast_to(turned(np.array([-math.sin(ti), 0.0, math.cos(ti)]), -rotation),
                                  (int(keep.sum()), 3)))
    wo_all = np.concatenate(wo)
    return _reduced(path, np.concatenate(wi), wo_all, np.concatenate(bsdf), None,
                    wo_all[:, 2] < 0, meta, options)
