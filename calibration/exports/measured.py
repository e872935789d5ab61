"""Reduced data as named columns, the one layout every export of measured values shares (and
the plain CSV that `--import` reads): sample-frame angles in degrees (theta_o above 90 for
transmission), the BSDF, its standard uncertainty u (`sigma`), the coverage factor k, U = k u,
one `u_NAME` column per budget component, validity and flags; plus the reduced CSV itself. Text
exports write angles rounded to ANGLE_DECIMALS (angle_text) and the values as they are."""

from __future__ import annotations

import csv
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from calibration.reduced import ReducedData
from gonio.record import record_lines

DEFAULT_COVERAGE_K = 2.0
QUANTITY = "BSDF (not cosine-corrected), 1/sr"
ANGLE_COLUMNS = ("theta_i_deg", "phi_i_deg", "theta_o_deg", "phi_o_deg")
# The reduction's scalar facts an export carries (the per-point lists and the emulator's
# [sim] table stay out: the record, gonio.record.run_record, says what the run was).
META_KEYS = ("eta", "k", "kind", "lit_from", "wavelength_nm", "aperture_half_angle_deg",
             "aperture_sr", "aperture_from", "beam_divergence_deg", "noise_model",
             "beam_mean_w", "beam_drift_rms", "calibration", "coverage_k", "sample", "optics",
             "assumption", "budget")
#: Decimals of the angles in degrees that text exports write: 1e-9 deg, far below the stages'
#: steps (about 1e-4 deg), so rounding drops float noise (29.999999999999996) and nothing
#: measured.
ANGLE_DECIMALS = 9
#: The source's azimuth in gonio's sample frame (the source on -x), degrees: the files that
#: name one incidence azimuth per point (ASTM, BiRD) write it at normal incidence too, whose
#: own azimuth is undefined, so that an isotropic run names one source azimuth throughout.
SOURCE_AZIMUTH_DEG = 180.0


def angle_text(value: float, decimals: int = ANGLE_DECIMALS) -> str:
    """An angle as text: rounded to `decimals`, then the shortest repr (-0 written as 0)."""
    return repr(round(float(value), decimals) + 0.0)


def spherical_deg(w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(theta from +z, phi = atan2(y, x) in [0, 360)) of unit vectors, degrees."""
    theta = np.degrees(np.arctan2(np.hypot(w[:, 0], w[:, 1]), w[:, 2]))
    return theta, np.mod(np.degrees(np.arctan2(w[:, 1], w[:, 0])), 360.0)


def rounded_deg(degrees: np.ndarray, azimuth: bool = False) -> np.ndarray:
    """Angles in degrees rounded to ANGLE_DECIMALS (float noise dropped, -0 as 0); azimuths
    then taken into [0, 360), so that one nominal angle is one value."""
    out = np.round(np.asarray(degrees, dtype=np.float64), ANGLE_DECIMALS) + 0.0
    return np.mod(out, 360.0) + 0.0 if azimuth else out


def file_angles_deg(w: np.ndarray, normal_azimuth: float) -> tuple[np.ndarray, np.ndarray]:
    """(theta, phi) of directions as the ASTM and BiRD files write them: rounded (rounded_deg),
    phi along the normal (theta 0 or 180, whose azimuth is undefined) `normal_azimuth`: the
    source's, SOURCE_AZIMUTH_DEG, for incidence, 0 for the outgoing direction."""
    theta, phi = spherical_deg(w)
    theta = rounded_deg(theta)
    return theta, np.where((theta == 0.0) | (theta == 180.0), normal_azimuth,
                           rounded_deg(phi, azimuth=True))


def unit_vectors(theta_deg: np.ndarray, phi_deg: np.ndarray) -> np.ndarray:
    """(N, 3) unit vectors of spherical angles (theta from +z, phi from +x), degrees."""
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    return np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=1)


def coverage_k(data: ReducedData) -> float:
    """The coverage factor of the data's expanded uncertainty (meta["coverage_k"], else 2)."""
    return float(data.meta.get("coverage_k", DEFAULT_COVERAGE_K))


def columns(data: ReducedData) -> dict[str, np.ndarray]:
    """The data as named columns (see the module docstring), in the order files write them."""
    ti, pi = spherical_deg(data.wi)
    to, po = spherical_deg(data.wo)
    k = coverage_k(data)
    n = len(data.bsdf)
    wavelength = data.meta.get("wavelength_nm")
    out = {"theta_i_deg": ti, "phi_i_deg": pi, "theta_o_deg": to, "phi_o_deg": po,
           "bsdf": data.bsdf, "sigma": data.sigma, "k": np.full(n, k), "U": k * data.sigma}
    out.update({f"u_{name}": np.asarray(u) for name, u in data.components.items()})
    out["wavelength_nm"] = np.full(n, np.nan if wavelength is None else float(wavelength))
    out["valid"] = data.valid.astype(int)
    out["flags"] = np.array([f.replace(",", ";") for f in data.flags])
    return out


def meta_facts(data: ReducedData) -> dict:
    """The reduction's facts an export states (META_KEYS present in meta), with the quantity."""
    facts = {"quantity": QUANTITY, "coverage_k": coverage_k(data)}
    facts.update({key: data.meta[key] for key in META_KEYS if key in data.meta})
    return facts


def fact_lines(data: ReducedData, eta: float | None = None) -> list[str]:
    """meta_facts(data) as `key: JSON` lines, which every text export writes after the run's
    record (its first, `quantity`, marks where the record ends); `eta`: the index the file's
    tables were made with, where that is not the data's (a fit's)."""
    facts = meta_facts(data)
    if eta is not None:
        facts["eta"] = float(eta)
    return record_lines(facts)


#: A shared error's part in a point below this fraction of its largest part is float noise,
#: not a point the error is common to.
SHARED_NOISE = 1e-12


def shared_error_lines(data: ReducedData) -> list[str]:
    """Comment lines that state the errors the points share (ReducedData.shared_rel): which
    budget components they come from, and per shared error the points it is common to (parts
    below SHARED_NOISE of its largest left out as float noise), the range of its relative size
    and its signs; none for data whose points share no error. Plain text (not `key: JSON`), so
    `--import` passes over them."""
    shared = data.shared_rel[:, np.any(data.shared_rel != 0, axis=0)]
    if shared.shape[1] == 0:
        return []
    names = (data.meta.get("budget") or {}).get("shared") or ["(unnamed)"]
    lines = [f"shared errors: {shared.shape[1]}, from the components {', '.join(names)}; "
             "each is one error common to several points (the values carry S z, z ~ "
             "N(0, 1) each), the rest of u (sigma) is each point's own and independent; the "
             "NetCDF export holds S's correlation between points "
             "(bsdf_shared_error_correlation)"]
    for j, column in enumerate(shared.T, start=1):
        part = column[np.abs(column) > SHARED_NOISE * np.max(np.abs(column))]
        size = np.abs(part)
        low, high = float(size.min()), float(size.max())
        span = f"{high:.3g}" if high - low <= 1e-12 * high else f"{low:.3g} to {high:.3g}"
        lines.append(f"shared error {j}: common to {len(part)} of {len(column)} points, "
                     f"relative size {span}, {_signs(part)}")
    return lines


def _signs(part: np.ndarray) -> str:
    """The signs of a shared error's parts (z's sign is arbitrary, so only whether they
    differ says anything): one sign at every point (they move together), or how many of each
    (the two groups move against each other)."""
    positive, negative = int(np.sum(part > 0)), int(np.sum(part < 0))
    if not (positive and negative):
        return "one sign at every point"
    return (f"positive at {positive} points and negative at {negative} (which ones: the NetCDF "
            "export's correlation)")


def write_reduced_csv(data: ReducedData, out: Path, record: Sequence[str] = ()) -> Path:
    """CSV of columns(data) under `# key: JSON` lines: the run's record, then the reduction's
    facts (fact_lines), so that `--import` finds the record, the index and the noise model
    again; then the shared errors (shared_error_lines). Angles are written by angle_text, the
    rest by repr (every digit)."""
    cols = columns(data)
    angle = [name in ANGLE_COLUMNS for name in cols]
    with open(out, "w", newline="") as fh:
        for line in [*record, *fact_lines(data), *shared_error_lines(data)]:
            fh.write(f"# {line}\n")
        writer = csv.writer(fh)
        writer.writerow(cols)
        for row in zip(*cols.values(), strict=True):
            writer.writerow([v if isinstance(v, str) else angle_text(v) if is_angle
                             else repr(float(v)) for v, is_angle in zip(row, angle, strict=True)])
    return out
