"""Errors name where a bad value is in one form, `FILE: [TABLE] KEY: message`, whichever file
holds it: an instrument config, a plan (an array of tables, an inline range table), the
emulator's [sim] tables, a calibration file."""

from __future__ import annotations

import json
from pathlib import Path

from gonio_cli.main import main

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
SERIAL = EXAMPLES / "instruments" / "sim-serial.toml"
DEMO = EXAMPLES / "plans" / "demo.toml"


def error_of(capsys, *argv: str) -> str:
    """The one stderr line of a command that fails with exit status 2."""
    assert main(list(argv)) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1
    return err.rstrip("\n")


def edited(tmp_path: Path, source: Path, old: str, new: str) -> Path:
    text = source.read_text()
    assert old in text
    path = tmp_path / source.name
    path.write_text(text.replace(old, new, 1).replace('"../instruments/', f'"{SERIAL.parent}/'))
    return path


def test_a_config_key(tmp_path, capsys):
    cfg = edited(tmp_path, SERIAL, "averaging = 4", "averaging = 0")
    assert error_of(capsys, "plan", str(DEMO), "--instrument", str(cfg)) == (
        f"gonio plan: error: {cfg}: [detector] averaging: must be in [1, 100000], got 0")


def test_a_whole_table(tmp_path, capsys):
    cfg = edited(tmp_path, SERIAL, "averaging = 4", "averagin = 4")
    assert error_of(capsys, "plan", str(DEMO), "--instrument", str(cfg)).startswith(
        f"gonio plan: error: {cfg}: [detector]: unknown key 'averagin' (known: averaging,")


def test_a_key_of_an_inline_table_in_an_array_of_tables(tmp_path, capsys):
    plan = edited(tmp_path, DEMO, "step = 10.0 }", "step = -10.0 }")
    assert error_of(capsys, "plan", str(plan)) == (
        f"gonio plan: error: {plan}: [grid[0]] theta_o_deg.step: must be in (0, inf], got -10.0")


def test_a_key_of_the_emulators_tables(tmp_path, capsys):
    cfg = edited(tmp_path, SERIAL, "alpha = 0.394", "alpha = -1")
    assert error_of(capsys, "scan", str(DEMO), "--instrument", str(cfg), "--sim",
                    "--out", str(tmp_path / "runs")) == (
        f"gonio scan: error: {cfg}: [sim.sample] alpha: must be a number >= 0.0001 and <= 4, "
        "got -1")
    assert not (tmp_path / "runs").exists()


def test_a_key_of_a_calibration_file(tmp_path, capsys):
    cal = tmp_path / "cal.json"
    cal.write_text(json.dumps({"format": "gonio-calibration/1",
                               "detector": {"gain": {"0.001": {"value": "one"}}}}))
    assert error_of(capsys, "calibrate", "show", str(cal)).startswith(
        f"gonio calibrate: error: {cal}: [detector.gain] 0.001: must be {{value, sigma}} numbers")
