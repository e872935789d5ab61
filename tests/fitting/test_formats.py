"""The format registry (calibration.formats): every writer and reader it names loads, and a
measured file is read as the format its magic, its suffix or its first keyword says."""

from __future__ import annotations

import importlib

import pytest

from calibration.formats import FORMATS, PLAIN, WHATS, format_to_read


@pytest.mark.parametrize("name", sorted(FORMATS))
def test_every_writer_and_reader_named_loads(name):
    fmt = FORMATS[name]
    assert fmt.default_what in fmt.whats and set(fmt.whats) <= set(WHATS)
    assert all(callable(fmt.writer(what)) for what in fmt.whats)
    if fmt.reader:
        module, _, function = fmt.reader.partition(":")
        assert callable(getattr(importlib.import_module(module), function))


@pytest.mark.parametrize("name, text, expected", [
    ("a.nc", "", "netcdf"), ("a.csv", "CDF\x01", "netcdf"), ("a.txt", "\x89HDF\r\n", "netcdf"),
    ("a.CSV", "VARS a\n", "csv"), ("a.astm", "DataBegin\n", "astm"),
    ("a.bsdf", "", "zemax"), ("a.ZMX", "", "zemax"),
    ("a.txt", "# c\nVARS theta_i,value\n", "astm"), ("a", "Source Measured\nDataBegin\n", "zemax"),
    ("a.txt", "VARS a\nDataBegin\n", "astm"), ("a.xml", "theta_i,bsdf\n", PLAIN.name),
])
def test_a_file_is_read_as_its_magic_suffix_or_first_keyword_says(name, text, expected,
                                                                   tmp_path):
    path = tmp_path / name
    path.write_bytes(text.encode("latin-1"))
    assert format_to_read(path).name == expected
