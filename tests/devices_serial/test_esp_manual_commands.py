"""Every command of the ESP301 manual's command summary: docs/devices.md's table lists each one
as `sim.devices.esp_manual` does, and the emulator knows each one (never error 6): those it
does not model are 27 COMMAND NOT ALLOWED, the others run."""

import math
import re
from pathlib import Path

import pytest

from sim.devices.esp import EspEmulator
from sim.devices.esp_manual import COMMAND_SUMMARY
from sim.devices.motion import VirtualClock

DOCS = Path(__file__).resolve().parents[2] / "docs" / "devices.md"
ROW = re.compile(r"\| `([A-Z]{2})` \| ([^|]+) \| (yes|no) \| (yes|no) \| ([^|]+) \|")


def docs_table() -> dict[str, tuple[str, str, str, str]]:
    """{mnemonic: (meaning, emulator, driver, note)} from docs/devices.md's ESP command table."""
    rows = {}
    for match in ROW.finditer(DOCS.read_text()):
        mnemonic, *cells = match.groups()
        assert mnemonic not in rows, f"{mnemonic} listed twice"
        rows[mnemonic] = tuple(cell.strip() for cell in cells)
    return rows


def test_docs_table_lists_the_whole_summary_as_the_emulator_does():
    rows = docs_table()
    assert list(rows) == list(COMMAND_SUMMARY) and len(rows) == 127
    for mnemonic, command in COMMAND_SUMMARY.items():
        meaning, emulated, _, note = rows[mnemonic]
        assert meaning == command.meaning
        assert emulated == ("yes" if command.emulated else "no"), mnemonic
        if not command.emulated:
            assert note == command.not_emulated


def test_docs_counts_match_the_table():
    rows = docs_table()
    emulated = sum(row[1] == "yes" for row in rows.values())
    driver = sum(row[2] == "yes" for row in rows.values())
    text = " ".join(DOCS.read_text().split())
    assert f"has {len(rows)} mnemonics. The emulator implements {emulated} of them" in text
    assert f"gonio's driver uses {driver}." in text


@pytest.mark.parametrize("mnemonic", [m for m, c in COMMAND_SUMMARY.items() if not c.emulated])
def test_a_command_not_emulated_is_not_allowed_never_unknown(mnemonic):
    emu = EspEmulator(VirtualClock(math.inf), {1: {}})
    for line in (f"1{mnemonic}", f"1{mnemonic}?", f"{mnemonic}1"):
        assert emu.handle_line(line.encode()) is None
        assert emu.handle_line(b"TE?") == b"27\r\n", line


@pytest.mark.parametrize("mnemonic", [m for m, c in COMMAND_SUMMARY.items() if c.emulated])
def test_an_emulated_command_runs(mnemonic):
    """Each emulated command's query (or, for a command without one, the command itself) runs
    without error 6 or 27."""
    emu = EspEmulator(VirtualClock(math.inf), {1: {"motor_on": True}})
    emu.handle_line(f"1{mnemonic}?".encode())
    codes = {code for code, _ in emu.errors}
    if codes & {6, 7}:  # no query form: run the command bare
        emu.errors.clear()
        emu.handle_line(f"1{mnemonic}".encode())
        codes = {code for code, _ in emu.errors}
    assert not codes & {6, 27}, (mnemonic, codes)
