"""An ABg fit as one entry of Zemax OpticStudio's ABg scatter data catalog, with the fields the
OpticStudio manual gives an entry ("ABg Scatter Data Catalogs"): its Name; Wave, the wavelength
in micrometres at which the data are defined (0: OpticStudio does not scale A and B with
wavelength); and up to 10 rows of Use, Angle (incidence, degrees, 0 to 90; OpticStudio
interpolates between rows linearly in cosine and holds the first and last row beyond them), A,
B and g, with BSDF = A / (B + |beta - beta0|^g) ("Available Scatter Models", the definitions of
model.bsdf.families.abg).

A fit has one (A, B, g) at every incidence, so the entry has one row, at angle 0, which
OpticStudio holds at every incidence. The manual asks for TIS < 1; the file states the fit's
TIS at a few incidences (ABg.total_integrated_scatter) and the export notes any at or above 1.

The layout, one `Keyword value ...` line per field, `#` comments, is gonio's: OpticStudio
publishes the entry's fields, not the syntax of its catalog files (ABg_Data/*.DAT), which its
catalog dialog writes. Enter the fields there (Libraries, ABg Scatter Data Catalogs, Insert;
docs/fitting.md, "Exports of the model families")."""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calibration.exports.family_fit import FamilyFit, check_family

#: Incidence angles (deg) at which the file states the entry's TIS.
TIS_ANGLES_DEG = (0.0, 30.0, 60.0, 85.0)
#: OpticStudio's bound on a data row's TIS for accurate scattering.
MAX_TIS = 1.0
#: An entry's name: what the catalog dialog takes as one word.
NAME_CHARACTERS = re.compile(r"[^A-Za-z0-9_]")


@dataclass(frozen=True)
class AbgEntry:
    """One catalog entry: name, wavelength (um; 0 for none) and rows of (use, angle, A, B, g)."""

    name: str
    wave_um: float
    rows: tuple[tuple[bool, float, float, float, float], ...]


def entry_name(text: str) -> str:
    """A catalog name from `text` (a file's stem): letters, digits and _, upper case."""
    return NAME_CHARACTERS.sub("_", text).upper() or "GONIO"


def abg_entry(family: FamilyFit, name: str, wavelength_nm: float | None) -> AbgEntry:
    """The entry of an ABg fit: one row at angle 0 with the fitted A (times the fit's scale), B
    and g; Wave the data's wavelength, 0 where the data give none."""
    check_family("abg", family.family)
    v = family.values
    wave = 0.0 if wavelength_nm is None else round(float(wavelength_nm) / 1000.0, 12)
    return AbgEntry(entry_name(name), wave,
                    ((True, 0.0, family.scale * v["A"], float(v["B"]), float(v["g"])),))


def entry_tis(family: FamilyFit) -> np.ndarray:
    """The fit's TIS (directional albedo, scale included) at TIS_ANGLES_DEG."""
    t = np.radians(TIS_ANGLES_DEG)
    wi = np.stack([np.sin(t), np.zeros_like(t), np.cos(t)], axis=-1)
    return family.scale * family.model().total_integrated_scatter(wi)


def tis_notes(family: FamilyFit) -> tuple[list[str], list[str]]:
    """(the file's TIS line, the export's notes: one where a TIS reaches MAX_TIS)."""
    tis = entry_tis(family)
    line = ("TIS (hemispherical scatter of the fitted model) " + " / ".join(
        f"{x:.6g}" for x in tis) + " at incidence " + " / ".join(
        f"{a:g}" for a in TIS_ANGLES_DEG) + " deg")
    if np.all(tis < MAX_TIS):
        return [line], []
    return [line], [f"abg: the fitted model scatters TIS {float(tis.max()):.4g} at "
                    f"{TIS_ANGLES_DEG[int(np.argmax(tis))]:g} deg incidence; OpticStudio "
                    f"needs TIS < {MAX_TIS:g} for accurate scattering"]


def write_abg(entry: AbgEntry, path: str | Path, comments: Sequence[str]) -> Path:
    """Write the entry: comments, then `Name`, `Wave` and one `Row use angle A B g` line per
    row (numbers with every digit)."""
    path = Path(path)
    lines = [f"# {c}" for c in comments]
    lines += ["# one entry of Zemax OpticStudio's ABg scatter data catalog: Name, Wave (um), "
              "and rows of Use (1 or 0), Angle (deg), A, B, g",
              f"Name  {entry.name}", f"Wave  {entry.wave_um!r}"]
    lines += [f"Row  {int(use)}  {angle!r}  {a!r}  {b!r}  {g!r}"
              for use, angle, a, b, g in entry.rows]
    path.write_text("\n".join(lines) + "\n")
    return path
