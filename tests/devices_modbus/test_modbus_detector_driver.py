"""ModbusDetector driver against the emulated photodiode amplifier over TCP and a pty (RTU):
configuration registers, autorange and fixed ranges, saturation, averaging, zero, faults."""

import math

import numpy as np
import pytest

from drivers.base import Detector, DeviceError
from drivers.register_map import RegisterMapError
from sim.devices.photodiode import ConstantPower, PhotodiodeModel

RANGES = (1e-8, 1e-7, 1e-6, 1e-5, 1e-4, 1e-3, 1e-2)


class SettablePower:
    """A PowerSource a test can change, or make fail."""

    def __init__(self, power_w):
        self.value = power_w

    def power_w(self):
        if isinstance(self.value, Exception):
            raise self.value
        return self.value


def test_configure_writes_every_setting(rig, link):
    r = rig(*link)
    assert isinstance(r.detector, Detector)
    assert r.detector.ranges_w == r.detector.full_scales_w() == RANGES
    r.detector.configure(532.1, 25, 1e-6)
    assert r.detector.settings() == {"wavelength": 532.1, "averaging": 25.0, "autorange": 0.0,
                                     "gain_range": 2.0}
    r.detector.configure(1064.0, 1, None)
    assert r.detector.settings()["autorange"] == 1.0
    assert r.detector_emu.registers.get("wavelength") == pytest.approx(1064.0)


def test_reading_matches_an_independent_model_with_the_same_seed(rig, link):
    r = rig(*link)
    r.detector.configure(632.8, 4, None)
    got = [r.detector.read() for _ in range(3)]
    model = PhotodiodeModel({"ranges_w": list(RANGES)}, seed=3)
    for reading in got:
        expect = model.measure(1e-5, None, 4, 632.8)
        assert reading.power_w == np.float32(expect.reading_w)  # float32 on the wire
        assert reading.range_w == expect.range_w == 1e-4  # autorange: 1e-5 > 0.9 * 1e-5
        assert reading.saturated is False


def test_fixed_range_saturates_and_autorange_recovers(rig):
    r = rig("rtu", source=ConstantPower(5e-4))
    r.detector.configure(632.8, 1, 1e-5)
    low = r.detector.read()
    assert low.saturated and low.range_w == 1e-5
    assert low.power_w == pytest.approx(1.1e-5, rel=1e-3)  # clipped at 1.1 x full scale
    assert r.detector.bits(r.detector.read_value("status"))["saturated"]
    r.detector.configure(632.8, 1, None)
    high = r.detector.read()
    assert not high.saturated and high.range_w == 1e-3
    assert high.power_w == pytest.approx(5e-4, rel=1e-3)


def test_range_request_picks_smallest_range_holding_it(rig):
    r = rig("tcp")
    assert r.detector.range_index(3e-7) == 2
    assert r.detector.range_index(1e-7) == 1
    with pytest.raises(ValueError, match="above the largest range"):
        r.detector.range_index(0.5)


def test_averaging_narrows_the_spread_as_one_over_sqrt_n(rig):
    r = rig("tcp", source=ConstantPower(2e-7))
    spreads = {}
    for n in (1, 16):
        r.detector.configure(632.8, n, 1e-6)
        spreads[n] = np.std([r.detector.read().power_w for _ in range(120)], ddof=1)
    model = PhotodiodeModel({"ranges_w": list(RANGES)})
    for n, s in spreads.items():  # 120 samples: the std is within ~20 % at 3 sigma
        assert s == pytest.approx(model.expected_sigma_w(2e-7, 1e-6, n, 632.8), rel=0.25)
    assert spreads[1] / spreads[16] == pytest.approx(4.0, rel=0.35)


def test_zero_removes_the_dark_offset(rig):
    source = SettablePower(0.0)
    r = rig("tcp", source=source, detector={"dark_current_a": 4e-9, "read_noise_fraction": 0.0,
                                            "bandwidth_hz": 0.0})
    r.detector.configure(632.8, 1, 1e-7)
    dark = r.detector.read().power_w
    responsivity = 0.37 + (0.42 - 0.37) * (632.8 - 600) / 50  # silicon table, 600..650 nm
    assert dark == pytest.approx(4e-9 / responsivity, rel=1e-3)  # dark current / responsivity
    r.detector.zero()
    assert abs(r.detector.read().power_w) < 1e-11


def test_sensor_fault_is_a_device_error_until_the_signal_returns(rig, link):
    source = SettablePower(RuntimeError("fibre unplugged"))
    r = rig(*link, source=source)
    with pytest.raises(DeviceError, match="det: device error 1: photodiode signal invalid"):
        r.detector.read()
    v = r.detector.read_values("reading", "status", "fault_code")
    assert math.isnan(v["reading"]) and v["fault_code"] == 1
    source.value = math.inf
    with pytest.raises(DeviceError, match="device error 1"):
        r.detector.read()
    r.detector.clear_fault()
    assert r.detector.read_value("fault_code") == 0
    source.value = 3e-6
    assert r.detector.read().power_w == pytest.approx(3e-6, rel=1e-3)


@pytest.mark.parametrize("register, value", [
    ("gain_range", 7), ("autorange", 2), ("averaging", 0), ("averaging", 10001),
    ("wavelength", 2999), ("wavelength", 12001), ("command", 9)])
def test_emulator_refuses_bad_settings_with_exception_03(rig, register, value):
    r = rig("rtu")
    address = r.detector.map.register(register).address
    with pytest.raises(DeviceError, match="Modbus exception 03: illegal data value"):
        r.detector.link.write("det", address, [value], 2)  # raw words: a foreign host


def test_driver_refuses_bad_settings_before_writing(rig):
    r = rig("tcp")
    before = r.detector.settings()
    for args, match in [((632.8, 0, None), "averaging = 0 outside"),
                        ((200.0, 1, None), "wavelength = 200.0 outside"),
                        ((632.8, 1.5, None), "averaging must be an integer"),
                        ((632.8, 1, -1.0), "range must be a power > 0"),
                        ((632.8, 1, 1.0), "above the largest range")]:
        with pytest.raises((ValueError, RegisterMapError), match=match):
            r.detector.configure(*args)
    assert r.detector.settings() == before


def test_addresses_outside_the_map_give_exception_02(rig):
    r = rig("tcp")
    with pytest.raises(DeviceError, match="Modbus exception 02"):
        r.detector.link.write("det", 4, [0, 0], 2)  # command exists, holding 5 does not
    with pytest.raises(DeviceError, match="Modbus exception 02"):
        r.detector.link.read("det", "input", 4, 2, 2)
    assert r.detector.read_value("command") == 0  # the refused write stored nothing
