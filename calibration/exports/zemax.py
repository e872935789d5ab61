"""Zemax tabular BSDF files (the Radiant/Zemax "BSDF data interchange" text format): writer of a
fitted model tabulated about the specular direction (`Source Model`; the measured tables of
calibration.exports.zemax_measured say `Source Measured`), and a reader that parses it back.

File layout (one scatter type per file): `Source Measured | Model`, `Symmetry PlaneSymmetrical |
Asymmetrical`, `SpectralContent Monochrome`, `ScatterType BRDF | BTDF`, then the counts and
values of `SampleRotation`, `AngleOfIncidence`, `ScatterAzimuth`, `ScatterRadial`, an empty
line, `Monochrome`, `DataBegin`, and for each sample rotation and angle a `TIS <value>` line
followed by one row per azimuth of BSDF values (1/sr) at the radial angles, then `DataEnd`.

Angles as the format defines them: `AngleOfIncidence` is the direction of the specular
reflection (BRDF) or of the direct transmission (BTDF: the refracted angle asin(sin i / eta)
inside the medium for the hemisphere geometry); the radial angle is the angle between the
scattered direction and that specular direction; azimuth 0 points from the specular direction
toward the sample normal, azimuth 90 toward the sample frame's +y. TIS is the integral of
f |cos theta_o| over the side's hemisphere (the scattered fraction of the incident power).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from calibration.exports.measured import angle_text
from calibration.formats.limits import (
    MAX_POINTS,
    MeasuredFile,
    check_count,
    measured_file,
    text_lines,
)
from calibration.values import CalibrationError

SCATTER_TYPES = ("BRDF", "BTDF")
SYMMETRIES = ("PlaneSymmetrical", "Asymmetrical")
SOURCES = ("Measured", "Model")
HORIZON_COS = 1e-6  # |cos theta_o| below which a model table writes 0


@dataclass
class ZemaxTable:
    """The content of one tabular BSDF file; data[rotation, angle, azimuth, radial] in 1/sr."""

    scatter_type: str
    symmetry: str
    sample_rotation_deg: np.ndarray
    angle_deg: np.ndarray  # specular (BRDF) or direct-transmission (BTDF) angles
    azimuth_deg: np.ndarray
    radial_deg: np.ndarray
    data: np.ndarray
    tis: np.ndarray  # [rotation, angle]
    comments: list[str] = field(default_factory=list)
    source: str = "Model"  # Measured: measured blocks, the model only where there is no data


def specular_frame(angle_deg: float, scatter_type: str) -> tuple[np.ndarray, ...]:
    """(c, e0, e90): the specular direction in the sample frame, the unit vector from it toward
    the normal on its side (azimuth 0) and +y (azimuth 90)."""
    t = math.radians(angle_deg)
    side = 1.0 if scatter_type == "BRDF" else -1.0
    c = np.array([math.sin(t), 0.0, side * math.cos(t)])
    e0 = np.array([-math.cos(t), 0.0, side * math.sin(t)])
    return c, e0, np.array([0.0, 1.0, 0.0])


def scatter_directions(angle_deg: float, scatter_type: str, azimuth_deg: np.ndarray,
                       radial_deg: np.ndarray) -> np.ndarray:
    """Unit vectors (n_azimuth, n_radial, 3) of the table's grid for one angle."""
    c, e0, e90 = specular_frame(angle_deg, scatter_type)
    phi = np.radians(azimuth_deg)[:, None, None]
    r = np.radians(radial_deg)[None, :, None]
    return np.cos(r) * c + np.sin(r) * (np.cos(phi) * e0 + np.sin(phi) * e90)


def on_side(wo: np.ndarray, scatter_type: str) -> np.ndarray:
    """True where a direction lies in the hemisphere of the scatter type."""
    return wo[..., 2] > 0 if scatter_type == "BRDF" else wo[..., 2] < 0


def hemisphere_integral(f: Callable[[np.ndarray], np.ndarray], scatter_type: str,
                        angle_deg: float, width_deg: float) -> float:
    """Integral of f(wo) |cos theta_o| over the side's hemisphere, on polar coordinates about
    the specular direction (Gauss-Legendre in the radial angle, split at a few lobe widths so a
    narrow peak is resolved; trapezoid in azimuth)."""
    edges = np.unique(np.clip([0.0, 2 * width_deg, 8 * width_deg, 30 * width_deg, 180.0],
                              0.0, 180.0))
    x, w = np.polynomial.legendre.leggauss(48)
    radial, weight = [], []
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        radial.append(lo + (hi - lo) * 0.5 * (x + 1))
        weight.append(w * 0.5 * math.radians(hi - lo))
    radial_deg, w_r = np.concatenate(radial), np.concatenate(weight)
    n_az = 128
    azimuth_deg = (np.arange(n_az) + 0.5) * 360.0 / n_az
    wo = scatter_directions(angle_deg, scatter_type, azimuth_deg, radial_deg)
    inside = on_side(wo, scatter_type)
    value = np.where(inside, f(wo) * np.abs(wo[..., 2]), 0.0)
    area = np.sin(np.radians(radial_deg)) * w_r * (2.0 * math.pi / n_az)
    return float(np.sum(value * area[None, :]))


def standard_azimuth(isotropic: bool) -> np.ndarray:
    """The format's azimuths, degrees: 0..180 by 10 (plane-symmetric) or 0..360 by 10, the
    row at 360 repeating 0 (a reader which does not wrap azimuths, as libbsdf, would
    otherwise extrapolate between 350 and 360)."""
    return np.arange(0.0, 180.1 if isotropic else 360.1, 10.0)


def radial_grid(width_deg: float, n: int = 48) -> np.ndarray:
    """Radial angles from 0 to 180 deg: fine across a lobe of the given width, coarser beyond."""
    start = max(width_deg / 10.0, 1e-3)
    return np.unique(np.round(np.concatenate([[0.0], np.geomspace(start, 180.0, n)]), 6))


def tabulate(model_eval: Callable[[np.ndarray, np.ndarray], np.ndarray], scatter_type: str,
             incidence_deg: np.ndarray, eta: float, width_deg: float,
             isotropic: bool = True, comments: list[str] | None = None,
             nodes: tuple[np.ndarray, np.ndarray] = (np.zeros(0), np.zeros(0))) -> ZemaxTable:
    """Tabulate model_eval(wi, wo) (1/sr) at the given incidence angles on the format's grid,
    with `nodes` (azimuth, radial angles, degrees: the measured directions) added to it, so
    that a reader finds the model's value at each measured direction without interpolating."""
    if scatter_type not in SCATTER_TYPES:
        raise CalibrationError(f"zemax: scatter type must be BRDF or BTDF, got {scatter_type!r}")
    incidence_deg = np.asarray(incidence_deg, dtype=np.float64)
    if scatter_type == "BRDF":
        angles = incidence_deg
    else:
        angles = np.degrees(np.arcsin(np.sin(np.radians(incidence_deg)) / eta))
    azimuth = np.unique(np.concatenate([standard_azimuth(isotropic), nodes[0]]))
    radial = np.unique(np.concatenate([radial_grid(width_deg), nodes[1]]))
    data = np.zeros((1, len(angles), len(azimuth), len(radial)))
    tis = np.zeros((1, len(angles)))
    for k, (theta_i, angle) in enumerate(zip(incidence_deg, angles, strict=True)):
        ti = math.radians(theta_i)
        wi = np.array([-math.sin(ti), 0.0, math.cos(ti)]) + 0.0  # no -0 at normal incidence

        def f(wo: np.ndarray, wi: np.ndarray = wi) -> np.ndarray:
            return model_eval(np.broadcast_to(wi, wo.shape), wo)

        wo = scatter_directions(angle, scatter_type, azimuth, radial)
        # a node on the horizon (a measured one can fall there) scatters nothing
        data[0, k] = np.where(on_side(wo, scatter_type) & (np.abs(wo[..., 2]) > HORIZON_COS),
                              f(wo), 0.0)
        if azimuth[-1] == 360.0:  # the closing row: azimuth 0's cells, bit for bit
            data[0, k, -1] = data[0, k, 0]
        tis[0, k] = hemisphere_integral(f, scatter_type, angle, width_deg)
    return ZemaxTable(scatter_type, "PlaneSymmetrical" if isotropic else "Asymmetrical",
                      np.zeros(1), angles, azimuth, radial, data, tis, list(comments or []))


def turned(v: np.ndarray, angle_deg: float) -> np.ndarray:
    """Vectors (..., 3) turned by angle_deg about z (counter-clockwise seen from +z)."""
    c, s = math.cos(math.radians(angle_deg)), math.sin(math.radians(angle_deg))
    return np.stack([c * v[..., 0] - s * v[..., 1], s * v[..., 0] + c * v[..., 1], v[..., 2]],
                    axis=-1) + 0.0


def _angles(values: np.ndarray) -> str:
    """A grid of angles, degrees, tab-separated (measured.angle_text: no float noise)."""
    return "\t".join(angle_text(v) for v in values)


def write_zemax(table: ZemaxTable, path: str | Path) -> Path:
    """Write the table in the Zemax tabular BSDF format: angles by angle_text, values and TIS
    with every digit (repr)."""
    path = Path(path)
    lines = [f"# {c}" for c in table.comments]
    lines += [
        f"Source  {table.source}",
        f"Symmetry  {table.symmetry}",
        "SpectralContent  Monochrome",
        f"ScatterType  {table.scatter_type}",
        f"SampleRotation  {len(table.sample_rotation_deg)}", _angles(table.sample_rotation_deg),
        f"AngleOfIncidence  {len(table.angle_deg)}", _angles(table.angle_deg),
        f"ScatterAzimuth  {len(table.azimuth_deg)}", _angles(table.azimuth_deg),
        f"ScatterRadial  {len(table.radial_deg)}", _angles(table.radial_deg),
        "", "Monochrome", "DataBegin",
    ]
    for r in range(len(table.sample_rotation_deg)):
        for a in range(len(table.angle_deg)):
            lines.append(f"TIS  {float(table.tis[r, a])!r}")
            lines += ["\t".join(repr(float(v)) for v in row) for row in table.data[r, a]]
    lines.append("DataEnd")
    path.write_text("\n".join(lines) + "\n")
    return path


def read_zemax(source: str | Path | MeasuredFile) -> ZemaxTable:
    """Parse a Zemax tabular BSDF file (monochrome) within calibration.formats.limits (its
    grid's size checked before it is allocated); errors name the line that is wrong."""
    file = measured_file(source)  # read once, within the limits
    path = file.path
    comments: list[str] = []
    body: list[tuple[int, str]] = []
    for n, line in text_lines(file):
        text = line.strip()
        if text.startswith("#"):
            comments.append(text[1:].strip())
        elif text:
            body.append((n, text))
    pos = 0

    def fail(msg: str) -> CalibrationError:
        line_no = body[min(pos, len(body) - 1)][0] if body else 0
        return CalibrationError(f"{path}:{line_no}: {msg}")

    def keyword(name: str) -> str:
        nonlocal pos
        if pos >= len(body):
            raise fail(f"expected {name}, found end of file")
        parts = body[pos][1].split()
        if parts[0] != name or len(parts) != 2 or len(parts[1]) > 40:
            raise fail(f"expected '{name} <value>', found {body[pos][1][:60]!r}")
        pos += 1
        return parts[1]

    def numbers(what: str, count: int) -> np.ndarray:
        """The `count` numbers of the line at pos, which then moves past it."""
        nonlocal pos
        try:
            values = np.array([float(v) for v in body[pos][1].split()] if pos < len(body)
                              else [])
        except ValueError:
            raise fail(f"{what}: not numbers: {body[pos][1][:60]!r}") from None
        if len(values) != count:
            raise fail(f"{what}: {count} values announced, {len(values)} given")
        pos += 1
        return values

    def enumeration(name: str) -> np.ndarray:
        count = keyword(name)
        if not (count.isascii() and count.isdigit() and len(count) <= 15):
            raise fail(f"{name}: the count must be a whole number (at most 15 digits), got "
                       f"{count[:20]!r}")
        check_count(path, int(count), f"values of {name}", MAX_POINTS)
        return numbers(name, int(count))

    source = keyword("Source")
    if source not in SOURCES:
        raise fail(f"Source must be Measured or Model, got {source!r}")
    symmetry = keyword("Symmetry")
    if symmetry not in SYMMETRIES:
        raise fail(f"Symmetry {symmetry!r} not supported ({', '.join(SYMMETRIES)})")
    if keyword("SpectralContent") != "Monochrome":
        raise fail("only Monochrome spectral content is supported")
    scatter_type = keyword("ScatterType")
    if scatter_type not in SCATTER_TYPES:
        raise fail(f"ScatterType must be BRDF or BTDF, got {scatter_type!r}")
    rotation, angle = enumeration("SampleRotation"), enumeration("AngleOfIncidence")
    azimuth, radial = enumeration("ScatterAzimuth"), enumeration("ScatterRadial")
    for expected in ("Monochrome", "DataBegin"):
        if pos >= len(body) or body[pos][1] != expected:
            raise fail(f"expected {expected}")
        pos += 1
    shape = (len(rotation), len(angle), len(azimuth), len(radial))
    check_count(path, math.prod(shape), "grid values (" + " x ".join(map(str, shape)) + ")",
                MAX_POINTS)
    data = np.zeros(shape)
    tis = np.zeros((len(rotation), len(angle)))
    for r in range(len(rotation)):
        for a in range(len(angle)):
            tis[r, a] = _number(keyword("TIS"), fail)
            for z in range(len(azimuth)):
                data[r, a, z] = numbers("data row", len(radial))
    if pos >= len(body) or body[pos][1] != "DataEnd":
        raise fail("expected DataEnd")
    return ZemaxTable(scatter_type, symmetry, rotation, angle, azimuth, radial, data, tis, comments,
                      source)


def _number(text: str, fail: Callable[[str], CalibrationError]) -> float:
    """The number `text` of a keyword's value; fail's error if it is not one."""
    try:
        return float(text)
    except ValueError:
        raise fail(f"not a number: {text!r}") from None


def tis_weights(table: ZemaxTable, angle: int) -> np.ndarray:
    """(n_azimuth, n_radial) weights w with TIS = sum(w * data[rotation, angle]): the
    trapezoid rule over the grid of f |cos theta_o| sin r dr dphi, mirrored for
    plane-symmetric data (so a TIS is linear in the tabulated values, and so is its error)."""
    wo = scatter_directions(table.angle_deg[angle], table.scatter_type, table.azimuth_deg,
                            table.radial_deg)
    r = np.radians(table.radial_deg)
    phi = np.radians(table.azimuth_deg)
    w_r = _trapezoid_weights(r)
    if table.symmetry == "PlaneSymmetrical":
        w_phi = 2.0 * _trapezoid_weights(phi)
    elif table.azimuth_deg[-1] == 360.0:  # closed by a row repeating azimuth 0
        w_phi = _trapezoid_weights(phi)
    else:  # closed over 2 pi: the last interval wraps to the first azimuth
        w_phi = _trapezoid_weights(np.append(phi, 2 * math.pi))
        w_phi[0] += w_phi[-1]
        w_phi = w_phi[:-1]
    return w_phi[:, None] * w_r[None, :] * np.abs(wo[..., 2]) * np.sin(r)[None, :]


def _trapezoid_weights(x: np.ndarray) -> np.ndarray:
    """Weights of the trapezoid rule on nodes x."""
    w = np.zeros(len(x))
    d = np.diff(x)
    w[:-1] += d / 2
    w[1:] += d / 2
    return w
