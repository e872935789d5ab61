"""Write a table `gonio fit --import` reads from NIST's measured BRDF of sintered PTFE (Germer
2017, the unmodified `PTFE.data.csv`; README.md beside this script): the unpolarised BRDF f_r11
at one wavelength, in the plane of incidence (default) or over the hemisphere, with the scatter
over azimuth at normal incidence that states its noise.

    python examples/data/nist_ptfe_table.py PTFE.data.csv OUT.csv [--wavelength-nm 532]
        [--hemisphere]
"""

from __future__ import annotations

import argparse
import csv
import sys
from pathlib import Path

import numpy as np

#: the columns of PTFE.data.csv this script reads (its README: lambda in micrometres, angles in
#: degrees, f_r11 in 1/sr)
COLUMNS = ("lambda", "thetai", "thetar", "phir", "f_r11")
SOURCE = ("T. A. Germer (NIST), sintered PTFE, Applied Optics 2017, PTFE.data.csv "
          "(figshare 10.6084/m9.figshare.5417410)")


class TableError(ValueError):
    """A source file or an option this script cannot use, with what is wrong."""


def read_source(path: Path) -> dict[str, np.ndarray]:
    """The COLUMNS of NIST's PTFE.data.csv, by name (a TableError names a missing column, a
    cell that is not a number, or a file without rows)."""
    with path.open(newline="") as handle:
        rows = list(csv.reader(handle))
    if len(rows) < 2:
        raise TableError(f"{path}: no data rows under a header of column names")
    header = [name.strip() for name in rows[0]]
    missing = [name for name in COLUMNS if name not in header]
    if missing:
        raise TableError(f"{path}: not NIST's PTFE.data.csv: no column {', '.join(missing)}")
    out = {}
    for name in COLUMNS:
        k = header.index(name)
        try:
            out[name] = np.array([float(row[k]) for row in rows[1:]])
        except (ValueError, IndexError):
            raise TableError(f"{path}: column {name} holds a cell that is not a number") from None
    return out


def gonio_rows(source: dict[str, np.ndarray], wavelength_nm: float,
               in_plane: bool) -> np.ndarray:
    """(N, 5) rows theta_i_deg, phi_i_deg, theta_o_deg, phi_o_deg, bsdf at one wavelength, in
    gonio's frame: source at phi_i = 0, mirror direction at phi_o = 180. NIST's signed incidence
    (thetai <= 0 at phi 0) puts the source at azimuth 180 of its frame, the mirror direction at
    phir = 0 (where the forward lobe at 75 degrees lies), so phi_o = phir + 180. In plane: the
    rows at phir 0 or 180 and the one at the normal."""
    available = sorted({round(v * 1000.0, 3) for v in source["lambda"]})
    at = np.isclose(source["lambda"] * 1000.0, wavelength_nm)
    if not at.any():
        raise TableError(f"no data at {wavelength_nm:g} nm; the file has "
                         + ", ".join(f"{v:g}" for v in available) + " nm")
    phir = source["phir"]
    if in_plane:
        at &= np.isclose(np.sin(np.radians(phir)), 0.0, atol=1e-6) | (source["thetar"] < 0.01)
    n = int(at.sum())
    return np.column_stack([np.abs(source["thetai"][at]), np.zeros(n), source["thetar"][at],
                            np.mod(phir[at] + 180.0, 360.0), source["f_r11"][at]])


def azimuthal_scatter(source: dict[str, np.ndarray], wavelength_nm: float) -> float:
    """The median over theta_r of the relative standard deviation of f_r11 over phir at normal
    incidence, where an isotropic sample's BRDF does not depend on phir: its noise and
    anisotropy together, the sigma that `--sigma-relative` assumes."""
    at = np.isclose(source["lambda"] * 1000.0, wavelength_nm) & (np.abs(source["thetai"]) < 0.5)
    theta = np.round(source["thetar"][at], 2)
    value = source["f_r11"][at]
    spreads = [np.std(group, ddof=1) / np.mean(group)
               for group in (value[theta == t] for t in np.unique(theta)) if len(group) >= 3]
    if not spreads:
        raise TableError(f"no normal-incidence directions repeated over phir at "
                         f"{wavelength_nm:g} nm")
    return float(np.median(spreads))


def write_table(rows: np.ndarray, wavelength_nm: float, out: Path) -> None:
    """gonio's plain CSV of the rows, one wavelength_nm column and the source in a header line."""
    lines = [f'# source: "{SOURCE}"',
             "theta_i_deg,phi_i_deg,theta_o_deg,phi_o_deg,bsdf,wavelength_nm"]
    lines += [f"{ti:.4f},{pi:g},{to:.4f},{po:.4f},{f:.6g},{wavelength_nm:g}"
              for ti, pi, to, po, f in rows]
    out.write_text("\n".join(lines) + "\n")


def main(argv: list[str] | None = None) -> int:
    """Write the table; print its size and the azimuthal scatter at normal incidence."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("source", type=Path, help="NIST's PTFE.data.csv, unmodified")
    parser.add_argument("out", type=Path, help="the table to write")
    parser.add_argument("--wavelength-nm", type=float, default=532.0,
                        help="351, 532, 633 or 1064 (default 532)")
    parser.add_argument("--hemisphere", action="store_true",
                        help="every direction measured, not the plane of incidence alone")
    args = parser.parse_args(argv)
    try:
        source = read_source(args.source)
        rows = gonio_rows(source, args.wavelength_nm, not args.hemisphere)
        scatter = azimuthal_scatter(source, args.wavelength_nm)
        write_table(rows, args.wavelength_nm, args.out)
    except (OSError, TableError) as exc:
        print(f"nist_ptfe_table: {exc}", file=sys.stderr)
        return 2
    incidences = ", ".join(f"{t:g}" for t in np.unique(np.round(rows[:, 0])))
    print(f"{args.out}: {len(rows)} points at incidences {incidences} deg; "
          f"scatter over azimuth at normal incidence {scatter:.4f} (relative, median)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
