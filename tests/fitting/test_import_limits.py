"""Hostile measured files given to `gonio fit --import`: sizes a file declares are checked
against calibration.formats.limits before anything is allocated, and every such file is one
error line naming it, exit 2, no traceback and a bounded peak memory."""

from __future__ import annotations

import os
import struct
from pathlib import Path

import numpy as np
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
    """The attack: an 8 KB NetCDF-4 file declaring 3e8 points (2.4 GB a variable; its chunks,
    never written, take no room)."""
    import netCDF4

    path = tmp_path / "huge.nc"
    with netCDF4.Dataset(path, "w", format="NETCDF4") as ds:
        ds.createDimension("point", 300_000_000)
        for name in REDUCED:
            ds.createVariable(name, "f8", ("point",), zlib=True, chunksizes=(1_000_000,))
    assert path.stat().st_size < 16_384
    refused(gonio_measured("fit", "--import", path), path,
            f"300000000 values of variable theta_i; an import holds at most {MAX_POINTS}")


def test_classic_netcdf_declaring_more_data_than_it_holds(tmp_path):
    """A classic file stores each value it declares: 3e8 points in 8 KB are refused by its
    header, before the library reads it."""
    path = tmp_path / "short.nc"
    path.write_bytes(classic_netcdf(300_000_000))
    refused(gonio_measured("fit", "--import", path), path,
            "variable theta_i declares 2400000000 bytes of data at byte 392, the file holds 8192")


def test_classic_netcdf_header_that_crashed_the_library(tmp_path):
    """A variable declaring 65535 dimensions in a 300-byte file: the netCDF library, which
    trusts its header, died of a segmentation fault opening it."""
    data = bytearray(classic_netcdf(3, 1024))
    ndims_at = data.index(b"theta_i") + 8
    data[ndims_at:ndims_at + 4] = struct.pack(">i", 65535)
    path = tmp_path / "crash.nc"
    path.write_bytes(bytes(data))
    refused(gonio_measured("fit", "--import", path), path,
            "damaged NetCDF header at byte 64: 65535 dimensions of a variable declared, more "
            "than the file's 1024 bytes hold")


@pytest.mark.parametrize("fmt", ["NETCDF3_CLASSIC", "NETCDF3_64BIT_OFFSET", "NETCDF3_64BIT_DATA"])
def test_classic_netcdf_of_another_program_is_read(fmt, tmp_path):
    """The header walk passes each classic variant the library writes, attributes, a record
    dimension and a scalar included."""
    import netCDF4

    path = tmp_path / "classic.nc"
    with netCDF4.Dataset(path, "w", format=fmt) as ds:
        ds.title, ds.counts = "another program's", np.arange(5)
        ds.createDimension("point", 4)
        ds.createDimension("time", None)
        for name in REDUCED:
            var = ds.createVariable(name, "f8", ("point",))
            var[:] = [10.0, 20.0, 30.0, 40.0] if name.startswith("theta") else 0.5
            var.units = "degree"
        ds.createVariable("when", "i2", ("time",))[:] = [1, 2, 3]
        ds.createVariable("wavelength", "f4")[...] = 632.8
    data = read_measured(path, ImportOptions(eta=1.5))
    assert len(data.bsdf) == 4 and data.meta["wavelength_nm"] == pytest.approx(632.8)


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
