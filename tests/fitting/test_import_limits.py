"""Hostile measured files given to `gonio fit --import`: sizes a file declares are checked
against calibration.formats.limits before anything is allocated, and every such file is one
error line naming it, exit 2, no traceback and a bounded peak memory."""

from __future__ import annotations

import os
import struct
from pathlib import Path

import pytest
from hostile_files import gonio_measured, refused

from calibration.formats.limits import MAX_FILE_BYTES, MAX_POINTS
from calibration.imports import ImportOptions, read_measured
from calibration.values import CalibrationError

REDUCED = ("theta_i", "phi_i", "theta_o", "phi_o", "bsdf", "bsdf_standard_uncertainty",
           "bsdf_expanded_uncertainty")
CSV_HEADER = "theta_i_deg,phi_i_deg,theta_o_deg,phi_o_deg,bsdf,sigma\n"


def _name(text: str) -> bytes:
    raw = text.encode()
    return struct.pack(">i", len(raw)) + raw + b"\0" * (-len(raw) % 4)


def classic_netcdf(points: int, file_bytes: int = 8192) -> bytes:
    """A NetCDF-3 (64-bit offset) file of `file_bytes` whose header declares a dimension of
    `points` and gonio's reduced variables (doubles) over it: the header only, no data."""
    header = b"CDF\x02" + struct.pack(">i", 0)
    header += struct.pack(">ii", 10, 1) + _name("point") + struct.pack(">i", points)
    header += struct.pack(">ii", 0, 0) + struct.pack(">ii", 11, len(REDUCED))
    variables = [_name(n) + struct.pack(">ii", 1, 0) + struct.pack(">ii", 0, 0)
                 + struct.pack(">iI", 6, min(8 * points, 2**32 - 1)) for n in REDUCED]
    begin = len(header) + sum(len(v) + 8 for v in variables)
    header += b"".join(v + struct.pack(">q", begin + k * 8 * points)
                       for k, v in enumerate(variables))
    return header.ljust(file_bytes, b"\0")


def zemax_header(angles: int, azimuths: int, radials: int) -> str:
    """A Zemax tabular BSDF file whose grid announces angles x azimuths x radials values and
    holds none of them."""
    def numbers(n: int) -> str:
        return " ".join(str(k % 90) for k in range(n))

    return "\n".join([
        "Source Measured", "Symmetry Asymmetrical", "SpectralContent Monochrome",
        "ScatterType BRDF", "SampleRotation 1", "0", f"AngleOfIncidence {angles}",
        numbers(angles), f"ScatterAzimuth {azimuths}", numbers(azimuths),
        f"ScatterRadial {radials}", numbers(radials), "Monochrome", "DataBegin", "TIS 1",
        "DataEnd"]) + "\n"


def test_netcdf_declaring_3e8_points_is_refused_before_reading(tmp_path):
    """The attack: an 8 KB NetCDF declaring 3e8 points (2.4 GB a variable)."""
    path = tmp_path / "huge.nc"
    path.write_bytes(classic_netcdf(300_000_000))
    refused(gonio_measured("fit", "--import", path), path,
            f"300000000 values of variable theta_i; an import holds at most {MAX_POINTS}")


def test_classic_netcdf_declaring_more_data_than_it_holds(tmp_path):
    """Within the point limit, a classic file still stores each value it declares."""
    path = tmp_path / "short.nc"
    path.write_bytes(classic_netcdf(MAX_POINTS))
    with pytest.raises(CalibrationError, match=rf"short.nc: declares {7 * 8 * MAX_POINTS} bytes "
                                               r"of data, the file holds 8192"):
        read_measured(path)


def test_zemax_header_asking_for_terabytes(tmp_path):
    """The attack: a small Zemax header whose grid would take 13 TiB."""
    path = tmp_path / "huge.bsdf"
    path.write_text(zemax_header(2000, 30_000, 30_000))
    assert path.stat().st_size < 300_000
    refused(gonio_measured("fit", "--import", path), path,
            f"1800000000000 grid values (1 x 2000 x 30000 x 30000); an import holds at most "
            f"{MAX_POINTS}")


def test_zemax_count_that_is_not_a_number(tmp_path):
    path = tmp_path / "bad.bsdf"
    path.write_text(zemax_header(1, 1, 1).replace("ScatterRadial 1", "ScatterRadial 1e9"))
    with pytest.raises(CalibrationError, match=r"bad.bsdf:\d+: ScatterRadial: the count must be "
                                               r"a whole number"):
        read_measured(path)


def test_csv_field_over_the_csv_modules_limit(tmp_path):
    """The attack: a 200,000-character field (the csv module stops at 131,072)."""
    path = tmp_path / "wide.csv"
    path.write_text(CSV_HEADER.replace("sigma", "flags") + "0,0,10,0,1," + "x" * 200_000 + "\n")
    refused(gonio_measured("fit", "--import", path, "--eta", "1.5", "--sigma-relative", "0.1"),
            path, "wide.csv:2: not CSV (field larger than field limit (131072))")


def test_csv_over_the_size_limit_is_refused_unread(tmp_path):
    """A file over MAX_FILE_BYTES (sparse: it costs no disk) is refused by its size."""
    path = tmp_path / "big.csv"
    with open(path, "w") as fh:
        fh.write(CSV_HEADER + "0,0,10,0,1,0.1\n")
        fh.truncate(MAX_FILE_BYTES + 1)
    refused(gonio_measured("fit", "--import", path), path,
            f"measured file is {MAX_FILE_BYTES + 1} bytes, over the {MAX_FILE_BYTES}-byte limit")


def test_csv_with_more_rows_than_an_import_holds(tmp_path):
    """The 39 MB CSV of the attack, cut to what shows the limit: the row past MAX_POINTS ends
    the reading with one error, in bounded memory."""
    path = tmp_path / "long.csv"
    path.write_text(CSV_HEADER + "0,0,10,0,1,0.1\n" * (MAX_POINTS + 1))
    refused(gonio_measured("fit", "--import", path, "--eta", "1.5"), path,
            f"{MAX_POINTS + 1} data rows or more; an import holds at most {MAX_POINTS}")


def test_csv_at_the_row_limit_is_read(tmp_path):
    path = tmp_path / "full.csv"
    path.write_text(CSV_HEADER + "0,0,10,0,1,0.1\n" * MAX_POINTS)
    assert len(read_measured(path, ImportOptions(eta=1.5)).bsdf) == MAX_POINTS


def test_astm_with_too_many_columns(tmp_path):
    path = tmp_path / "wide.astm"
    names = ",".join(["THETAI", "PHII", "THETAS", "PHIS"] + [f"{k}nm" for k in range(400, 500)])
    path.write_text(f"VARS {names}\n")
    with pytest.raises(CalibrationError, match=r"wide.astm: 104 columns; an import holds at "
                                               r"most 64"):
        read_measured(path)


@pytest.mark.parametrize("kind", ["device", "fifo", "directory"])
def test_import_of_what_is_not_a_regular_file(kind, tmp_path):
    """/dev/zero, a FIFO no one writes (opening it must not wait for a writer) and a folder."""
    path = {"device": Path("/dev/zero"), "fifo": tmp_path / "pipe.csv",
            "directory": tmp_path}[kind]
    if kind == "fifo":
        os.mkfifo(path)
    what = {"device": "a character device", "fifo": "a FIFO", "directory": "a directory"}[kind]
    refused(gonio_measured("fit", "--import", path), path,
            f"measured file must be a regular file, not {what}")
