"""Strict numeric reply shapes: a reply that lost a byte is a ProtocolError, not a number.

Unit level: every single-byte deletion of an NR3 (PM100) or fixed-point (ESP) reply is
rejected, except the few that keep the shape (a minus sign; an ESP integer digit), which
no format check can see. End to end: seeded dropped bytes over real ptys, many reads, and
every number that reaches the caller is exactly what the emulator sent.
"""

import pytest
from garbling import reads_through_faults
from hypothesis import given, settings
from hypothesis import strategies as st
from waiting import HANG_S

from drivers.base import ProtocolError
from drivers.esp import decimal_parser
from drivers.pm100 import nr3_parser
from sim.devices.faults import FaultInjector, FaultSpec

QUIET = {"read_noise_fraction": 1e-3, "dark_current_a": 0.0, "bandwidth_hz": 0.0}
nr3 = nr3_parser()
fixed = decimal_parser()


def _deletions(text):
    return [(i, text[:i] + text[i + 1:]) for i in range(len(text))]


def _accepts(parse, text):
    try:
        parse(text)
    except (ProtocolError, ValueError):
        return False
    return True


@settings(max_examples=300, deadline=None)
@given(st.floats(1e-15, 1e3) | st.floats(-1e3, -1e-15), st.booleans())
def test_nr3_rejects_every_deletion_but_the_sign(value, plus):
    text = f"{value:+.6E}" if plus else f"{value:.6E}"
    assert nr3(text) == float(text)
    for i, garbled in _deletions(text):
        assert _accepts(nr3, garbled) == (i == 0 and text[0] in "+-"), garbled


@settings(max_examples=300, deadline=None)
@given(st.floats(-1e4, 1e4))
def test_fixed_point_rejects_deletions_outside_the_integer_digits(value):
    text = f"{value:.5f}"
    assert fixed(text) == float(text)
    point = text.index(".")
    digits = point - text.startswith("-")
    for i, garbled in _deletions(text):
        keeps_shape = text[i] == "-" or (i < point and digits >= 2)
        assert _accepts(fixed, garbled) == keeps_shape, garbled


def test_lax_float_parsing_would_have_let_wrong_numbers_through():
    """Why the shapes are checked: float() reads most of these deletions as other numbers."""
    text = "1.234567E-06"
    wrong = [g for _, g in _deletions(text) if _accepts(float, g) and float(g) != float(text)]
    assert len(wrong) == 10 and not any(_accepts(nr3, g) for g in wrong)


@pytest.mark.parametrize("text", ["1.234567E-6", "1.23456E-06", "1234567E-06", "1.234567E06",
                                  "1.234567e-06", " 1.234567E-06", "nan", "1.234567E-06 "])
def test_nr3_garbled_shapes_are_named(text):
    with pytest.raises(ProtocolError, match=f"garbled number '{text}'"):
        nr3(text)


def test_nr3_decimals_follow_the_configured_firmware_format():
    assert nr3_parser(8)("6.32800000E+02") == 632.8
    with pytest.raises(ProtocolError):
        nr3_parser(8)("6.328000E+02")


def test_pm100_no_garbled_reading_reaches_the_caller(pm_pair):
    """Every byte of every reply may be the dropped one; 400 seeded reads, retries on."""
    emu, pm = pm_pair(power_w=1.234567e-6, detector=QUIET, retries=10)
    emu.server.faults = FaultInjector(FaultSpec(drop_prob=0.5, seed=11))
    for _ in range(400):
        reading = pm.read()
        assert reading.power_w == float(f"{emu.last_reading:.6E}")
        assert reading.range_w == 1e-5
    assert emu.server.faults.counts["drop"] > 300


def test_pm100_without_retries_every_dropped_byte_is_a_protocol_error(pm_pair):
    """Numbers, separators and the `0,"No error"` status all have fixed shapes, so a reply
    that lost any byte (positive readings: no sign to lose) is rejected. Every reply ends, so
    the timeout is only a hang guard: a stall under load is not a dropped byte."""
    emu, pm = pm_pair(power_w=1.234567e-6, detector=QUIET, retries=0, timeout_s=HANG_S)
    emu.server.faults = FaultInjector(FaultSpec(drop_prob=1.0, seed=4))
    for _ in range(200):
        with pytest.raises(ProtocolError, match="pm100: "):
            pm.read()
    assert emu.server.faults.counts["drop"] == 200


def test_pm100_settings_read_back_strictly(pm_pair):
    emu, pm = pm_pair(retries=12)
    emu.server.faults = FaultInjector(FaultSpec(drop_prob=0.5, seed=6))
    for _ in range(40):
        assert pm.wavelength_nm == 632.8
        assert pm.averaging == 1
        assert pm.range_w is None
        assert pm.wavelength_limits_nm() == (400.0, 1100.0)


@pytest.mark.parametrize("position", [7.12345, 0.5, -0.25])
def test_esp_no_garbled_position_reaches_the_caller(esp_pair, position):
    """One integer digit: every dropped byte of the number breaks its shape."""
    emu, ctl = esp_pair(retries=0)
    axis = ctl.axis(1)
    axis.move_to(position)
    emu.server.faults = FaultInjector(FaultSpec(drop_prob=1.0, seed=8))
    values, garbled = reads_through_faults(axis.position, 200)
    # the drop hit the TB? timestamp (harmless) or, if negative, the sign
    assert all(value == position or (position < 0 and value == -position) for value in values)
    assert garbled > 50


def test_esp_multi_digit_positions_only_shape_keeping_drops_pass(esp_pair):
    """-123.45678: the only wrong values that can pass are a lost sign or integer digit
    (no checksum on the ESP); every other drop is rejected."""
    emu, ctl = esp_pair(retries=0)
    axis = ctl.axis(2)
    axis.move_to(-123.45678)
    text = "-123.45678"
    possible = {float(g) for i, g in _deletions(text) if i < text.index(".")}
    emu.server.faults = FaultInjector(FaultSpec(drop_prob=1.0, seed=3))
    values, _ = reads_through_faults(axis.position, 200)
    assert all(value == -123.45678 or value in possible for value in values)
    # the documented limit is real, not hidden by the seed
    assert sum(value != -123.45678 for value in values) > 0
