"""The two independent register-map readers (drivers.register_map for hosts, sim.devices.
register_map for emulators) against each other, against struct, and on broken map files."""

import math
import struct

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from modbus_testkit import DETECTOR_MAP, STAGE_MAP, with_word_order  # noqa: I001

from drivers.register_map import RegisterMap, RegisterMapError
from sim.devices.register_map import DeviceLayout, LayoutError, RegisterFile, Rejected


@pytest.fixture(scope="module")
def maps(tmp_path_factory):
    """{(kind, order): (host map, emulator layout)} for both shipped maps in both orders."""
    folder = tmp_path_factory.mktemp("maps")
    out = {}
    for kind, src in (("stage", STAGE_MAP), ("detector", DETECTOR_MAP)):
        for order in ("big", "little"):
            path = with_word_order(src, order, folder)
            out[kind, order] = RegisterMap.load(path), DeviceLayout.read(path)
    return out


def test_both_readers_agree_on_the_layout(maps):
    for host, emu in maps.values():
        assert set(host.registers) == set(emu.fields)
        for name, reg in host.registers.items():
            f = emu.fields[name]
            assert (reg.table, reg.address, reg.count, reg.scale, reg.writable) == (
                f.table, f.address, f.width, f.scale, f.writable)
        assert host.commands == emu.commands and host.status_bits == emu.bits
        assert {c.code: c.text for c in host.fault_codes.values()} == dict(emu.faults.values())
        assert host.gain_ranges_w == emu.ranges_w


def test_word_order_puts_the_high_word_first_or_last(maps):
    big, little = maps["stage", "big"][0], maps["stage", "little"][0]
    assert big.encode("target_position", 70.0) == [0x0001, 0x1170]  # 70000 = 0x00011170
    assert little.encode("target_position", 70.0) == [0x1170, 0x0001]
    assert big.encode("target_position", -0.001) == [0xFFFF, 0xFFFF]
    det = maps["detector", "little"][0]
    hi, lo = struct.unpack(">HH", struct.pack(">f", 1.5e-6))
    assert det.encode("reading", 1.5e-6) == [lo, hi]


@settings(max_examples=200, deadline=None)
@given(value=st.integers(-(2**31), 2**31 - 1), order=st.sampled_from(["big", "little"]))
def test_int32_round_trip_host_to_emulator(maps, value, order):
    host, emu = maps["stage", order]
    degrees = value / 1000.0
    words = host.encode("target_position", degrees)
    assert words == emu.to_words("target_position", degrees)
    assert emu.from_words("target_position", words) * 1000.0 == pytest.approx(value, abs=1e-6)
    raw = struct.unpack(">i", struct.pack(">HH", *(words if order == "big" else words[::-1])))
    assert raw[0] == value


@settings(max_examples=200, deadline=None)
@given(value=st.floats(width=32, allow_nan=False), order=st.sampled_from(["big", "little"]))
def test_float32_round_trip_emulator_to_host(maps, value, order):
    host, emu = maps["detector", order]
    words = emu.to_words("reading", value)
    assert host.decode("reading", words) == value
    assert words == host.encode("reading", value)


def test_nan_reading_survives_the_wire(maps):
    host, emu = maps["detector", "big"]
    assert math.isnan(host.decode("reading", emu.to_words("reading", math.nan)))


def test_uint32_and_scaled_uint16(maps):
    host, emu = maps["stage", "big"]
    assert host.decode("velocity", emu.to_words("velocity", 719.999)) == pytest.approx(719.999)
    det_host, det_emu = maps["detector", "big"]
    assert det_host.encode("wavelength", 632.8) == [6328] == det_emu.to_words("wavelength",
                                                                              632.8)
    assert np.float32(det_host.decode("wavelength", [6328])) == np.float32(632.8)


def test_host_encode_refuses_out_of_range_and_overflow(maps):
    host = maps["stage", "big"][0]
    with pytest.raises(RegisterMapError, match=r"velocity = 0.0 outside \[0.001, 720.0\] deg/s"):
        host.encode("velocity", 0.0)
    with pytest.raises(RegisterMapError, match="does not fit a int32"):
        host.encode("target_position", 2.2e6)
    with pytest.raises(RegisterMapError, match="no register 'speed'"):
        host.encode("speed", 1.0)


def test_emulator_words_saturate_instead_of_wrapping(maps):
    emu = maps["stage", "big"][1]
    assert emu.from_words("target_position", emu.to_words("target_position", 1e9)) == (
        (2**31 - 1) / 1000)


def test_block_reads_cover_registers_and_take_them_apart(maps):
    host = maps["stage", "little"][0]
    table, first, count = host.block(("fault_code", "actual_position", "status"))
    assert (table, first, count) == ("holding", 7, 4)
    words = [3, *host.encode("actual_position", -12.5), 0b1001]
    assert host.take("actual_position", first, words) == -12.5
    assert host.take("status", first, words) == 9
    with pytest.raises(RegisterMapError, match="not in one table"):
        maps["detector", "big"][0].block(("reading", "averaging"))


def test_register_file_refuses_like_a_device(maps):
    regs = RegisterFile(maps["stage", "big"][1])
    with pytest.raises(Rejected, match="exception 2: holding register 15 is not in the map"):
        regs.read("holding", 14, 2)
    with pytest.raises(Rejected, match="exception 2: register status is read-only"):
        regs.write(10, [0])
    assert regs.write(0, [0, 5]) and regs.get("target_position") == 0.005


BROKEN = [
    ('word_order = "big"', 'word_order = "middle"', "word_order must be"),
    ('name = "stepper-drive"', "", "missing field 'name'"),
    ('type = "uint16"\naccess = "r"', 'type = "int64"\naccess = "r"', "type must be one of"),
    ('table = "holding"\naddress = 2', 'table = "coil"\naddress = 2', "table must be one of"),
    ("address = 13", "address = 12", "overlap"),
    ("address = 13", "address = 65535", "past the 16-bit address space"),
    ("scale = 1000.0\nunit = \"deg/s\"", "scale = -1.0\nunit = \"deg/s\"", "scale must be > 0"),
    ("code = 1,", 'code = "one",', "code must be a int"),
    ("start = 1 ", "start = -1 ", "start must be an integer >= 0"),
    ("[status_bits]    #", "[gain_ranges]\nfull_scale_w = [1e-3, 1e-4]\n[status_bits] #",
     "full_scale_w: must be increasing powers"),
]


@pytest.mark.parametrize("old, new, message", BROKEN)
def test_broken_map_files_are_named_errors(tmp_path, old, new, message):
    text = STAGE_MAP.read_text()
    assert old in text
    path = tmp_path / "broken.toml"
    path.write_text(text.replace(old, new, 1))
    with pytest.raises(RegisterMapError, match=message) as err:
        RegisterMap.load(path)
    assert str(path) in str(err.value)


@pytest.mark.parametrize("text", ["word_order = 'big'\n[registers.x]\ntype = 'int8'\n"
                                  "table = 'holding'\naddress = 0", "not toml ["])
def test_emulator_reader_refuses_broken_maps(tmp_path, text):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(LayoutError, match=str(path)):
        DeviceLayout.read(path)
    with pytest.raises(RegisterMapError, match=str(path)):
        RegisterMap.load(path)


def test_a_section_that_is_not_a_table_is_named(tmp_path):
    path = tmp_path / "flat.toml"
    path.write_text('name = "x"\nword_order = "big"\ncommands = 5\n[registers]\n')
    with pytest.raises(RegisterMapError, match=r"\[commands\]: must be a table, got 5"):
        RegisterMap.load(path)


def test_missing_file_is_named(tmp_path):
    with pytest.raises(RegisterMapError, match="no-such.toml: cannot read register map"):
        RegisterMap.load(tmp_path / "no-such.toml")


@pytest.mark.parametrize("value", [-1.797693134862316e305, 1e306])
def test_a_value_whose_scaling_overflows_is_a_clear_error(value):
    # millidegrees of 1e306 deg overflow float64 to inf: refused, not an OverflowError
    with pytest.raises(RegisterMapError, match="does not fit a int32 register"):
        RegisterMap.load(STAGE_MAP).encode("target_position", value)
