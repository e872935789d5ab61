"""`gonio export --help` says that a Zemax export of a two-sided run is two files (Zemax reads
a BRDF and a BTDF from separate files) and that each path written is printed; the export
itself is tested end to end in tests/fitting/test_fitting_emulated_bench.py."""

from __future__ import annotations

import pytest

from gonio_cli.main import main


def test_export_help_names_both_zemax_files(capsys):
    with pytest.raises(SystemExit) as done:
        main(["export", "--help"])
    assert done.value.code == 0
    text = " ".join(capsys.readouterr().out.split())
    assert "one file per measured side" in text and "STEM-BRDF.SUFFIX" in text
    assert "Every file written is printed, one per line" in text
