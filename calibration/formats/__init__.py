"""The file formats of `gonio export --format` and `--import`, each declared once: its name,
suffixes, default `--what`, its writer per `--what`, its reader and how a file of it is known.

`gonio export` (calibration.exports) takes its choices, defaults, suffix checks and writers
from here, `--import` (calibration.imports) its readers and `format_to_read`. Adding a format is
one entry here pointing at its writers (and reader).
"""

from __future__ import annotations

from pathlib import Path

from calibration.formats.file_format import WHATS, FileFormat
from calibration.formats.limits import MeasuredFile, measured_file
from calibration.formats.sniff import first_keyword

_WRITERS = "calibration.exports.writers"

FORMATS: dict[str, FileFormat] = {fmt.name: fmt for fmt in (
    FileFormat(name="csv", suffixes=(".csv",), default_what="reduced",
               writers={"raw": "calibration.exports.raw:write_csv",
                        "reduced": f"{_WRITERS}:reduced_csv"},
               reader="calibration.imports:from_csv"),
    FileFormat(name="netcdf", suffixes=(".nc",), default_what="reduced",
               writers={"raw": "calibration.exports.raw:write_netcdf",
                        "reduced": f"{_WRITERS}:reduced_netcdf"},
               reader="calibration.imports:from_netcdf", magic=(b"CDF", b"\x89HDF")),
    FileFormat(name="bluesky", suffixes=(".jsonl",), default_what="raw",
               writers={"raw": "calibration.exports.bluesky:write_jsonl"}),
    FileFormat(name="zemax", suffixes=(".bsdf", ".zmx", ".txt"), default_what="reduced",
               writers={"reduced": f"{_WRITERS}:reduced_zemax", "model": f"{_WRITERS}:model_zemax"},
               reader="calibration.imports:from_zemax", keyword="DataBegin"),
    FileFormat(name="astm", suffixes=(".astm", ".txt"), default_what="reduced",
               writers={"reduced": f"{_WRITERS}:reduced_astm", "model": f"{_WRITERS}:model_astm"},
               reader="calibration.imports:from_astm", keyword="VARS"),
    FileFormat(name="bird", suffixes=(".json",), default_what="reduced",
               writers={"reduced": f"{_WRITERS}:reduced_bird"},
               reader="calibration.imports:from_bird"),
    FileFormat(name="mitsuba", suffixes=(".xml",), default_what="model",
               writers={"model": f"{_WRITERS}:model_mitsuba"}),
    FileFormat(name="abg", suffixes=(".abg", ".txt"), default_what="model",
               writers={"model": f"{_WRITERS}:model_abg"}),
)}

#: What a file that no format's magic, suffix or keyword claims is read as: a plain CSV of
#: named columns (its reader names the columns it lacks).
PLAIN = FORMATS["csv"]


def formats_with_suffix(suffix: str) -> list[FileFormat]:
    """The formats whose files may end in `suffix` (any case)."""
    return [fmt for fmt in FORMATS.values() if suffix.lower() in fmt.suffixes]


def format_to_read(source: str | Path | MeasuredFile) -> FileFormat:
    """The format to read a measured file as (its bytes read once, limits.measured_file): the
    one whose magic it starts with, else the one its suffix names (a suffix of one format
    only), else the one whose keyword a line of it starts with first, else PLAIN."""
    file = measured_file(source)
    readable = [fmt for fmt in FORMATS.values() if fmt.reader]
    by_magic = [fmt for fmt in readable if fmt.magic and file.data.startswith(fmt.magic)]
    if by_magic:
        return by_magic[0]
    named = formats_with_suffix(file.path.suffix)
    if len(named) == 1 and named[0].reader:
        return named[0]
    keywords = {fmt.keyword: fmt for fmt in readable if fmt.keyword}
    found = first_keyword(file.data, keywords)
    return PLAIN if found is None else keywords[found]


__all__ = ["FORMATS", "PLAIN", "WHATS", "FileFormat", "format_to_read", "formats_with_suffix"]
