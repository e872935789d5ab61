"""The declared settings' pieces on their own: commands built from values, the read-back rule
of each setting (to the reply's precision, a fixed range as that very range), and the two
status dialects' split of a reply into answers and status."""

import pytest

from drivers.esp import TB_DIALECT, EspAxis, decimal_parser
from drivers.pm100 import ERR_DIALECT, Pm100, nr3_parser

FIXED, NR3 = decimal_parser(), nr3_parser()


@pytest.mark.parametrize(("sent", "got", "taken"), [
    (12.345678, 12.34568, True),  # five decimals show 12.345678 as 12.34568
    (12.345678, 12.34567, False),
    (45.0, 45.0, True),
    (45.0, 45.00001, False),  # one unit in the last place off
    (-0.000004, 0.0, True),
])
def test_esp_rates_read_back_to_five_decimals(sent, got, taken):
    assert EspAxis.speed_deg_s.check(sent, got, FIXED) is taken


@pytest.mark.parametrize(("sent", "got", "taken"), [
    (632.8, 632.8, True),
    (632.81234567, 632.8123, True),  # NR3: 6.328123E+02
    (632.8, 632.8001, False),
    (1e-4, 1.000001e-4, False),  # the same decade, one unit of the mantissa's last digit
    (9.9999996e-5, 1e-4, True),  # rounds up into the next decade
])
def test_pm100_wavelength_reads_back_to_the_nr3_mantissa(sent, got, taken):
    assert Pm100.wavelength_nm.check(sent, got, NR3) is taken


@pytest.mark.parametrize(("sent", "got", "taken"), [
    (1e-4, 1e-4, True),
    (1e-4, 1e-6, False),  # some fixed range, not the one asked for
    (1e-4, None, False),  # still autoranging
    (None, None, True),
    (None, 1e-4, False),
])
def test_a_pm100_range_reads_back_as_that_range(sent, got, taken):
    assert Pm100.range_w.check(sent, got, NR3) is taken


def test_commands_are_built_from_the_declared_format():
    assert Pm100.range_w.command_for(None) == ":SENS:POW:RANG:AUTO ON"
    assert Pm100.range_w.command_for(1e-4) == ":SENS:POW:RANG 1.000000E-04"
    assert Pm100.averaging.command_for(16.0) == ":SENS:AVER:COUN 16"
    assert Pm100.wavelength_nm.command_for(632.8) == ":SENS:CORR:WAV 632.8"
    assert EspAxis.speed_deg_s.command_for(12.5) == "VA12.5"
    assert EspAxis.enabled.command_for(False) == "MF"
    assert Pm100.range_w.value(True, 1e-3) is None and Pm100.range_w.value(False, 1e-3) == 1e-3


def test_half_a_unit_in_the_last_place():
    assert FIXED.half_unit(123.0) == pytest.approx(5e-6)
    assert NR3.half_unit(3.3e-6) == pytest.approx(5e-13)
    assert NR3.half_unit(0.0) == pytest.approx(5e-7)


def test_the_dialects_split_answers_from_the_status():
    assert TB_DIALECT.split("ESP301 Version 3.0, 12/03,0, 17, NO ERROR DETECTED", 1) == (
        ["ESP301 Version 3.0, 12/03"], "0, 17, NO ERROR DETECTED")
    assert TB_DIALECT.split("1,12.50000,0, 17, NO ERROR DETECTED", 2) == (
        ["1", "12.50000"], "0, 17, NO ERROR DETECTED")
    assert TB_DIALECT.status("10, 17, NO ERROR DETECTED") is None  # a merged "1" and "0"
    assert TB_DIALECT.status("106, 17, POSITIVE SOFTWARE LIMIT DETECTED") == (
        106, "POSITIVE SOFTWARE LIMIT DETECTED")
    assert ERR_DIALECT.split('1.000000E-06;0,"No error"', 1) == (
        ["1.000000E-06"], '0,"No error"')
    assert ERR_DIALECT.status('10,"No error"') is None
    assert ERR_DIALECT.status('-222,"Data out of range"') == (-222, "Data out of range")
