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

from calibration.exports.bird_read import MAX_JSON_STRINGS, MAX_JSON_VALUES
from calibration.exports.cf import read_reduced_netcdf
from calibration.formats import format_to_read
from calibration.formats.limits import MAX_FILE_BYTES, MAX_POINTS, MeasuredFile, measured_file
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


def bird_json(path: Path, points: int, value: str = "0", size: int = 0) -> Path:
    """A BiRD file of `points` points, each angle and BRDF `value` (its text as JSON), and a
    comment that makes it `size` bytes long."""
    values = ",".join([value] * points)
    variables = ",".join(f'"{name}": {{"unit": "{unit}", "values": [{values}]}}'
                         for name, unit in (("theta_i", "deg"), ("phi_i", "deg"),
                                            ("theta_r", "deg"), ("phi_r", "deg"),
                                            ("BRDF", "1/sr")))
    text = f'{{"data": {{{variables}}}, "comment": ""}}'
    path.write_text(text.replace('""', '"' + "x" * (size - len(text)) + '"'))
    return path


def test_bird_json_of_millions_of_points_is_refused_before_parsing(tmp_path):
    """The attack: a 65 MB BiRD file of 6.5 million points (896 MB when parsed whole)."""
    path = bird_json(tmp_path / "huge.json", 6_500_000)
    assert 60e6 < path.stat().st_size <= MAX_FILE_BYTES
    refused(gonio_measured("fit", "--import", path), path,
            f"32500035 JSON values (counted by their separators); an import holds at most "
            f"{MAX_JSON_VALUES}")


def test_bird_json_at_the_value_cap_is_parsed_in_bounded_memory(tmp_path):
    """As many JSON values as the cap lets in (floats, the costliest that are not strings),
    with a string filling the file up to MAX_FILE_BYTES: parsed within the memory limit, then
    refused by their count of points."""
    points = (MAX_JSON_VALUES - 40) // 5
    path = bird_json(tmp_path / "full.json", points, "1.5", MAX_FILE_BYTES)
    assert path.stat().st_size == MAX_FILE_BYTES
    refused(gonio_measured("fit", "--import", path), path,
            f"{points} values of data.BRDF; an import holds at most {MAX_POINTS}")


def test_bird_json_of_many_strings_is_refused_before_parsing(tmp_path):
    """Short strings cost the most once parsed: a file of more than the cap of them."""
    path = bird_json(tmp_path / "strings.json", MAX_JSON_STRINGS // 5 + 1, '"ab"')
    refused(gonio_measured("fit", "--import", path), path,
            f"{MAX_JSON_STRINGS + 28} JSON strings (counted by their quotes); an import holds "
            f"at most {MAX_JSON_STRINGS}")


def test_bird_json_of_more_points_than_an_import_holds(tmp_path):
    path = bird_json(tmp_path / "long.json", MAX_POINTS + 1)
    with pytest.raises(CalibrationError, match=rf"long.json: {MAX_POINTS + 1} values of "
                                               rf"data.BRDF; an import holds at most "
                                               rf"{MAX_POINTS}"):
        read_measured(path)


def test_the_netcdf_library_reads_the_bytes_that_were_checked(tmp_path):
    """The file is read once (limits.measured_file): its header walk and the library both
    read those bytes, never the path again, so a file put in its place after the read (here:
    a damaged header for a good file, then a good file for a damaged header) is not read."""
    import netCDF4

    good, bad = tmp_path / "good.nc", tmp_path / "bad.nc"
    with netCDF4.Dataset(good, "w", format="NETCDF3_64BIT_OFFSET") as ds:
        ds.createDimension("point", 2)
        for name in REDUCED:
            ds.createVariable(name, "f8", ("point",))[:] = [10.0, 20.0]
    bad.write_bytes(classic_netcdf(300_000_000))
    checked = measured_file(good)
    bad.replace(good)  # the path now holds the damaged header; the bytes read are the good file
    assert len(read_reduced_netcdf(checked).bsdf) == 2
    with pytest.raises(CalibrationError, match="declares 2400000000 bytes of data"):
        read_reduced_netcdf(MeasuredFile(good, classic_netcdf(300_000_000)))


def test_the_format_is_told_from_the_bytes_read(tmp_path):
    """Sniffing reads no file: a FIFO at the path is never opened by it."""
    fifo = tmp_path / "measured.txt"
    os.mkfifo(fifo)
    assert format_to_read(MeasuredFile(fifo, b"# a comment\nVARS THETAI\n")).name == "astm"
    assert format_to_read(MeasuredFile(fifo, b"CDF\x01")).name == "netcdf"
