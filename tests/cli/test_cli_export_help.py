"""`gonio export --help` says that a Zemax export of a two-sided run is two files (Zemax reads
a BRDF and a BTDF from separate files), that each path written is printed and what each format
holds; a format asked for what it does not hold is one error line. The export itself is tested
end to end in tests/fitting/test_fitting_emulated_bench.py and test_exports_measured.py."""

from __future__ import annotations

from pathlib import Path

import pytest

from calibration.formats import FORMATS
from gonio_cli.main import main


def test_export_help_names_both_zemax_files(capsys):
    with pytest.raises(SystemExit) as done:
        main(["export", "--help"])
    assert done.value.code == 0
    text = " ".join(capsys.readouterr().out.split())
    assert "one file per measured side" in text and "STEM-BRDF.SUFFIX" in text
    assert "Every file written is printed, one per line" in text
    assert "zemax: reduced or model (default reduced)" in text and "--fit FIT.json" in text
    assert "csv and netcdf write the raw readings of a run that cannot be reduced" in text


def test_export_help_says_what_provenance_gives(capsys):
    """--provenance FILE.toml: the tables and keys a BiRD export takes at export time."""
    with pytest.raises(SystemExit):
        main(["export", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "[--provenance FILE.toml]" in text
    assert ("[provenance], [environment], [optics] (only source_name, source_type, "
            "source_power_mw, u_source_power_mw, detector_spectral_range_nm) and [sample] (only "
            "shape, azimuth_reference, diameter_mm, length_mm, width_mm, thickness_mm)") in text
    assert "fills only what the run lacks" in text and "sha256" in text


@pytest.mark.parametrize("fmt,what", [("zemax", "raw"), ("csv", "model"), ("mitsuba", "raw")])
def test_export_refuses_what_a_format_does_not_hold(fmt, what, tmp_path, capsys):
    assert main(["export", str(tmp_path), "--format", fmt, "--what", what,
                 "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (f"gonio export: error: export: --what {what} is not written as {fmt} (it "
                   f"takes {' or '.join(FORMATS[fmt].whats)})")


@pytest.mark.parametrize("argv", [
    ["export", "RUN", "--format", "foo", "--out", "x.csv"],
    ["export", "RUN", "--format", "csv", "--what", "bogus", "--out", "x.csv"],
    ["lut", "--kind", "bogus", "--out", "x.npz"],
    ["export", "RUN"],
    ["no-such-verb"],
])
def test_a_usage_error_is_one_line_naming_help(argv, capsys):
    with pytest.raises(SystemExit) as stop:
        main(argv)
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "error:" in err and "--help)" in err
    assert "usage:" not in err


@pytest.mark.parametrize("fmt,out,hint", [("csv", "x.nc", ", which is --format netcdf's"),
                                          ("zemax", "x.astm", ", which is --format astm's"),
                                          ("astm", "x.TXT", None), ("mitsuba", "x", "")])
def test_export_checks_the_suffix_before_any_work(fmt, out, hint, tmp_path, capsys):
    """One error line, before the run is opened (there is none here) or a file is written; a
    suffix of the format (any case) passes on to the missing run."""
    said = f"ends in {Path(out).suffix}" if Path(out).suffix else "has no suffix"
    assert main(["export", str(tmp_path / "no-run"), "--format", fmt,
                 "--out", str(tmp_path / out)]) == 2
    err = capsys.readouterr().err.strip()
    if hint is None:
        assert "no-run" in err and "--out" not in err
        return
    assert err == (
        f"gonio export: error: export: --out {tmp_path / out} {said}{hint}; --format {fmt} "
        f"writes {' or '.join(FORMATS[fmt].suffixes)}")
    assert list(tmp_path.iterdir()) == []
