"""Measured BSDF files that gonio did not make, read into the ReducedData that `fit` and
`reduce` use: ASTM E1392 (`.astm`), Zemax tabular BSDF (`.bsdf`, `.zmx`, `.txt` with its
keywords), gonio's reduced NetCDF (`.nc`) and CSV, or a plain CSV with named columns
(theta_i, phi_i, theta_o, phi_o in degrees, with or without `_deg`, theta_o above 90 for
transmission; bsdf; optional sigma and wavelength_nm).

Uncertainties come from the file where it has them (CSV `sigma`, NetCDF); otherwise from a
stated assumption (`sigma_relative`: u = that fraction of |bsdf|, put into meta["noise_model"]),
and a file with neither is one error naming it. The index comes from the file (a gonio CSV's
`# eta:` line, the NetCDF's attributes) or from `eta`.
"""

from __future__ import annotations

import csv
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calibration.exports.measured import ANGLE_COLUMNS, META_KEYS, unit_vectors
from calibration.reduced import ReducedData
from calibration.values import CalibrationError

ALIASES = {"bsdf_per_sr": "bsdf", "sigma_per_sr": "sigma"}  # `gonio reduce`'s reduced.csv


@dataclass(frozen=True)
class ImportOptions:
    """What a file may lack: the sample's index, and the relative standard uncertainty to
    assume where the file has no uncertainties."""

    eta: float | None = None
    sigma_relative: float | None = None


def read_measured(path: str | Path, options: ImportOptions | None = None) -> ReducedData:
    """The file's measurements as ReducedData (its format from the suffix, or, for a text
    file of another suffix, from its first keyword)."""
    path = Path(path)
    options = options or ImportOptions()
    if not path.is_file():
        raise CalibrationError(f"{path}: no such file")
    suffix = path.suffix.lower()
    if suffix == ".nc" or _starts_with(path, (b"CDF", b"\x89HDF")):
        from calibration.exports.cf import read_reduced_netcdf

        data = read_reduced_netcdf(path)
        data.meta.setdefault("assumption", "uncertainties as the file states them")
    elif suffix == ".astm" or (suffix != ".csv" and _has_line(path, "VARS")):
        data = _from_astm(path, options)
    elif suffix in (".bsdf", ".zmx") or (suffix != ".csv" and _has_line(path, "DataBegin")):
        data = _from_zemax(path, options)
    else:
        data = _from_csv(path, options)
    data.meta["imported_from"] = str(path)
    eta = options.eta if options.eta is not None else data.meta.get("eta")
    if eta is None:
        raise CalibrationError(f"{path}: the file gives no refractive index (eta), which the "
                               "fit needs for a dielectric; give it with --eta")
    data.meta["eta"] = float(eta)
    return data


def _starts_with(path: Path, magic: tuple[bytes, ...]) -> bool:
    """True when the file begins with one of the magic byte strings (NetCDF 3 or 4)."""
    with open(path, "rb") as fh:
        head = fh.read(8)
    return head.startswith(magic)


def _has_line(path: Path, keyword: str) -> bool:
    """True when a line of a text file starts with `keyword` (sniffing a format)."""
    try:
        with open(path, errors="replace") as fh:
            return any(line.split(maxsplit=1)[:1] == [keyword] for line in fh)
    except OSError as exc:
        raise CalibrationError(f"{path}: {exc.strerror}") from None


def _assumed_sigma(path: Path, bsdf: np.ndarray, options: ImportOptions,
                   what: str) -> tuple[np.ndarray, str]:
    """(sigma, the assumption stated) for a file without uncertainties; an error without
    sigma_relative."""
    if options.sigma_relative is None:
        raise CalibrationError(f"{path}: {what} has no uncertainties, which the fit needs; give "
                               "--sigma-relative FRACTION to assume u = FRACTION * |bsdf|")
    if not 0.0 < options.sigma_relative < 10.0:
        raise CalibrationError(f"{path}: --sigma-relative must be in (0, 10), got "
                               f"{options.sigma_relative!r}")
    sigma = options.sigma_relative * np.abs(bsdf)
    return sigma, (f"assumed: u = {options.sigma_relative:g} * |bsdf| (the file states no "
                   "uncertainties; --sigma-relative); values of 0 get no u from it and are "
                   "left out (flag 'zero')")


def _reduced(path: Path, wi: np.ndarray, wo: np.ndarray, bsdf: np.ndarray,
             sigma: np.ndarray | None, transmission: np.ndarray, meta: dict,
             options: ImportOptions, what: str) -> ReducedData:
    """ReducedData of imported samples; the noise model says where sigma comes from."""
    if sigma is None:
        sigma, meta["noise_model"] = _assumed_sigma(path, bsdf, options, what)
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


def _header(lines: list[str]) -> dict:
    """The `# key: JSON` lines of a gonio CSV (others are left out)."""
    out = {}
    for line in lines:
        key, sep, value = line[1:].strip().partition(": ")
        if sep:
            try:
                out[key] = json.loads(value)
            except ValueError:
                continue
    return out


def _from_csv(path: Path, options: ImportOptions) -> ReducedData:
    """A plain or gonio CSV (see the module docstring)."""
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise CalibrationError(f"{path}: not a readable text file ({exc})") from None
    lines = text.splitlines()
    meta = {k: v for k, v in _header([ln for ln in lines if ln.startswith("#")]).items()
            if k in META_KEYS}
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
    return _reduced(path, wi, wo, bsdf, sigma, wo[:, 2] < 0, meta, options, "the CSV")


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _from_astm(path: Path, options: ImportOptions) -> ReducedData:
    """An ASTM E1392 file: its first value column (one wavelength)."""
    from calibration.exports.astm import directions, read_astm

    table = read_astm(path)
    if table.values.shape[1] != 1:
        raise CalibrationError(f"{path}: {table.values.shape[1]} value columns (one per "
                               "wavelength); the fit takes one wavelength: split the file")
    wi, wo, transmission = directions(table)
    meta = {}
    if math.isfinite(table.wavelengths_nm[0]):
        meta["wavelength_nm"] = table.wavelengths_nm[0]
    return _reduced(path, wi, wo, table.values[:, 0], None, transmission, meta, options,
                    "an ASTM E1392 file")


def _from_zemax(path: Path, options: ImportOptions) -> ReducedData:
    """A Zemax tabular BSDF file: every grid value on its side's hemisphere (the file does
    not say which are measured, so the fit takes all of them), at its incidence angles
    (BTDF: recovered from the direct-transmission angle with `eta`)."""
    from calibration.exports.zemax import on_side, read_zemax, scatter_directions

    table = read_zemax(path)
    eta = options.eta
    if table.scatter_type == "BTDF" and eta is None:
        raise CalibrationError(f"{path}: a BTDF's incidence angles follow from its "
                               "direct-transmission angles only with the index: give --eta")
    wi, wo, bsdf = [], [], []
    for a, angle in enumerate(table.angle_deg):
        theta_i = (angle if table.scatter_type == "BRDF" else
                   math.degrees(math.asin(min(1.0, eta * math.sin(math.radians(angle))))))
        directions = scatter_directions(angle, table.scatter_type, table.azimuth_deg,
                                        table.radial_deg)
        keep = on_side(directions, table.scatter_type)
        keep &= np.abs(directions[..., 2]) > 1e-9
        keep[1:, table.radial_deg == 0.0] = False  # the specular direction, once
        if table.symmetry == "PlaneSymmetrical":
            inside = (table.azimuth_deg > 0) & (table.azimuth_deg < 180)
            mirrored = directions[inside] * np.array([1.0, -1.0, 1.0])
            directions = np.concatenate([directions, mirrored])
            values = np.concatenate([table.data[0, a], table.data[0, a][inside]])
            keep = np.concatenate([keep, keep[inside]])
        else:
            values = table.data[0, a]
        ti = math.radians(theta_i)
        wo.append(directions[keep])
        bsdf.append(values[keep])
        wi.append(np.broadcast_to([-math.sin(ti), 0.0, math.cos(ti)], (int(keep.sum()), 3)))
    wo_all = np.concatenate(wo)
    return _reduced(path, np.concatenate(wi), wo_all, np.concatenate(bsdf), None,
                    wo_all[:, 2] < 0, {}, options, "a Zemax tabular BSDF file")
