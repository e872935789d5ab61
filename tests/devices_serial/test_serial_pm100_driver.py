"""PM100 driver against its emulator over a real pty: SCPI commands, errors, timeouts, faults."""

import time

import numpy as np
import pytest
from waiting import wait_until

from drivers.base import (
    Detector,
    DeviceError,
    DeviceTimeout,
    DriverError,
    HeadRange,
    InvalidReading,
    ProtocolError,
    Reading,
)
from drivers.pm100 import Pm100, WavelengthOutsideHead
from sim.devices.faults import FaultInjector, FaultSpec
from sim.devices.motion import VirtualClock
from sim.devices.photodiode import ConstantPower
from sim.devices.pm100 import Pm100Emulator

QUIET = {"read_noise_fraction": 1e-3, "dark_current_a": 0.0, "bandwidth_hz": 0.0}


def inject(emu, **spec):
    emu.server.faults = FaultInjector(FaultSpec(**spec))


def raw(drv, line):
    return drv.transport.exchange(line)


def test_identity_and_sensor(pm_pair):
    emu, pm = pm_pair()
    assert isinstance(pm, Detector) and pm.name == "pm100"
    assert pm.idn.startswith("Thorlabs,PM100D,")
    s = pm.sensor()
    assert (s.name, s.type, s.flags & 1, s.flags & 32) == ("S121C", 1, 1, 32)
    assert raw(pm, "SYST:SENSOR:IDN?") == raw(pm, "system:sensor:idn?")
    sensor = emu.sensor
    assert pm.identity() == {"idn": emu.idn, "sensor_name": sensor.name,
                             "sensor_serial": sensor.serial,
                             "sensor_calibration": sensor.calibration,
                             "sensor_type": str(sensor.type), "sensor_subtype": str(sensor.subtype),
                             "sensor_flags": str(sensor.flags)}


def test_configure_and_read_back(pm_pair):
    emu, pm = pm_pair()
    pm.configure(wavelength_nm=850.0, averaging=16, range_w=1e-4)
    assert (pm.wavelength_nm, pm.averaging, pm.range_w) == (850.0, 16, 1e-4)
    assert (emu.wavelength_nm, emu.averaging, emu.autorange) == (850.0, 16, False)
    pm.configure(632.8, 1, None)
    assert pm.range_w is None and emu.autorange
    assert pm.wavelength_limits_nm() == (400.0, 1100.0)
    with pytest.raises(ValueError, match="averaging"):
        pm.configure(632.8, 0, None)


def test_a_wavelength_the_head_cannot_take_names_the_head_and_its_range(pm_pair):
    emu, pm = pm_pair()
    pm.configure(850.0, 4, None)
    with pytest.raises(WavelengthOutsideHead) as caught:
        pm.configure(1550.0, 2, 1e-4)
    assert str(caught.value) == ("pm100: wavelength 1550 nm is outside the sensor head S121C's "
                                 "range 400-1100 nm")
    assert isinstance(caught.value, DeviceError) and caught.value.code == -222
    assert (emu.wavelength_nm, emu.averaging, emu.autorange) == (850.0, 4, True)  # untouched
    assert pm.errors() == []  # the refusal was read with the command, nothing left queued
    pm.configure(1100.0, 2, None)  # the range's own bound is taken
    assert emu.wavelength_nm == 1100.0


def test_a_wavelength_just_past_the_range_is_named_as_asked(pm_pair):
    """1100.0004 nm on a 400-1100 nm head: the message says 1100.0004, never "1100 nm is
    outside 400-1100 nm"; asked without setting, the head's range gives the same answer."""
    emu, pm = pm_pair()
    with pytest.raises(WavelengthOutsideHead) as caught:
        pm.configure(1100.0004, 1, None)
    assert str(caught.value) == ("pm100: wavelength 1100.0004 nm is outside the sensor head "
                                 "S121C's range 400-1100 nm")
    assert str(WavelengthOutsideHead.asked(pm, 1100.0004)) == str(caught.value)
    assert WavelengthOutsideHead.asked(pm, 1100.0) is None
    assert WavelengthOutsideHead.asked(pm, 399.99).reason == (
        "wavelength 399.99 nm is outside the sensor head S121C's range 400-1100 nm")
    assert emu.wavelength_nm != 1100.0004 and pm.errors() == []


def test_the_meter_tells_its_heads_range_and_name_as_any_head_range_does(pm_pair):
    # gonio asks a detector's head through drivers.base's HeadRange (gonio devices' check of
    # the config's wavelength), never through the PM100's module
    emu, pm = pm_pair()
    assert isinstance(pm, HeadRange)
    assert (pm.wavelength_limits_nm(), pm.head_name()) == ((400.0, 1100.0), "S121C")


def test_full_scales_are_the_sensors_ranges_and_leave_the_setting_alone(pm_pair):
    emu, pm = pm_pair(detector={"ranges_w": [3e-8, 3e-7, 3e-6, 3e-5]})
    pm.configure(632.8, 1, 3e-6)
    assert pm.full_scales_w() == (3e-8, 3e-7, 3e-6, 3e-5) == emu.photodiode.ranges_w
    assert pm.range_w == 3e-6 and not emu.autorange
    pm.configure(632.8, 1, None)
    assert pm.full_scales_w() == (3e-8, 3e-7, 3e-6, 3e-5) and emu.autorange  # found once


def test_read_autoranges_and_matches_the_true_power(pm_pair):
    emu, pm = pm_pair(power_w=3.3e-6, detector=QUIET)
    reading = pm.read()
    assert isinstance(reading, Reading)
    assert reading.range_w == 1e-5 and not reading.saturated
    assert reading.power_w == pytest.approx(3.3e-6, abs=5e-8)
    assert pm.measure() == pytest.approx(3.3e-6, abs=5e-8)


def test_fixed_range_saturates(pm_pair):
    emu, pm = pm_pair(power_w=5e-6, detector=QUIET)
    pm.configure(632.8, 1, 1e-6)
    reading = pm.read()
    assert reading.saturated and reading.range_w == 1e-6
    assert reading.power_w == pytest.approx(1.1e-6)  # the ADC clips at 1.1 x full scale


def test_scpi_not_a_number_is_an_invalid_reading_not_an_over_range(pm_pair):
    emu, pm = pm_pair(power_w=5e-6, detector=QUIET)
    pm.configure(632.8, 1, 1e-6)
    inject(emu, invalid_prob=1.0)
    assert raw(pm, "READ?").startswith("9.910000E+37")
    with pytest.raises(InvalidReading, match=r"^pm100: invalid reading \(SCPI not-a-number "
                                             r"9.910000E\+37\) on the 1e-06 W range$"):
        pm.read()
    with pytest.raises(InvalidReading):
        pm.measure()
    inject(emu)  # the same light without the fault is over range: a power, flagged saturated
    assert pm.read().saturated


def test_invalid_readings_follow_the_seed():
    def pattern(seed):
        faults = FaultInjector(FaultSpec(invalid_prob=0.3, seed=seed))
        return [faults.invalid_reading() for _ in range(400)]

    assert pattern(7) == pattern(7) != pattern(8)
    assert abs(sum(pattern(7)) - 120) < 5 * (400 * 0.3 * 0.7) ** 0.5


def test_averaging_reduces_noise_as_one_over_sqrt_n(pm_pair):
    emu, pm = pm_pair(power_w=5e-6, detector={"read_noise_fraction": 5e-3})
    pm.configure(632.8, 1, 1e-5)
    single = np.std([pm.read().power_w for _ in range(150)])
    pm.averaging = 16
    averaged = np.std([pm.read().power_w for _ in range(150)])
    assert single / averaged == pytest.approx(4.0, rel=0.35)


def test_zero_removes_the_dark_offset(pm_pair):
    dark = {**QUIET, "dark_current_a": 1e-8}  # 1e-8 A / ~0.42 A/W = 2.4e-8 W offset
    emu, pm = pm_pair(power_w=0.0, detector=dark)
    pm.configure(632.8, 64, 1e-6)
    assert pm.read().power_w == pytest.approx(1e-8 / emu.photodiode.responsivity_a_w(632.8),
                                              rel=0.05)
    pm.zero()
    assert pm.zero_offset_w() > 2e-8
    assert abs(pm.read().power_w) < 2e-9


def test_init_fetch_and_conf(pm_pair):
    emu, pm = pm_pair(power_w=1e-6, detector=QUIET)
    assert pm.query("CONF?") == ["POW"]
    with pytest.raises(DeviceError, match="-230: Data corrupt or stale"):
        pm.query("CONF:POW;FETC?")
    (value,) = pm.query("INIT;FETC?")
    assert float(value) == pytest.approx(1e-6, abs=5e-8)  # 5 sigma of the read noise
    assert pm.query("FETCH?") == [value]  # fetch returns the same, stored reading


@pytest.mark.parametrize(
    "message",
    [
        "SENS:CORR:WAV 633",
        "SENSE:CORRECTION:WAVELENGTH 633",
        "sens:corr:wav 6.33e2",
        "Sense:Corr:Wavelength 633.0",
        "CORR:WAV 633",  # [SENSe] is optional
        ":SENS:CORR:WAV MIN;:SENS:CORR:WAV 633",
    ],
)
def test_short_long_and_case_forms(pm_pair, message):
    emu, pm = pm_pair()
    pm.query(message)
    assert emu.wavelength_nm == 633.0


def test_compound_header_path_rule(pm_pair):
    emu, pm = pm_pair()
    assert pm.query("SENS:CORR:WAV 700;WAV?;:SENS:POW:RANG:AUTO 0;AUTO?") == [
        "7.000000E+02", "0"]
    assert pm.query("MEAS:POW?;SYST:ERR?")[1] == '0,"No error"'  # root fallback
    pm.range_w = None  # autorange again (the fixed 10 mW range is too coarse for 2 uW)
    long_form = pm.query("MEASURE:POWER?;:SYSTEM:ERROR?;:MEASURE:SCALAR:POWER?")
    assert float(long_form[0]) > 0 and long_form[1] == '0,"No error"' and float(long_form[2]) > 0


@pytest.mark.parametrize(
    "message, code",
    [
        ("SENS:CORR:WAV 300", -222),  # below the sensor's range
        ("SENS:CORR:WAV abc", -104),
        ("SENS:CORR:WAV", -109),
        ("SENS:CORR:WAV 633,1", -108),
        ("SENS:AVER:COUN 2.5", -222),
        ("SENS:POW:RANG:AUTO MAYBE", -104),
        ("SENS:CORR:WAV? LOUD", -224),
        ("SENS:BOGUS 1", -113),
        ("SENSORS:CORR:WAV 633", -113),  # neither short nor long form
        ("*IDN? 3", -108),
        ("SENS::CORR:WAV 633", -102),
    ],
)
def test_scpi_error_codes(pm_pair, message, code):
    emu, pm = pm_pair()
    with pytest.raises(DeviceError) as err:
        pm.query(message)
    assert err.value.code == code and err.value.device == "pm100"


def test_error_queue_overflow_and_cls(pm_pair):
    emu, pm = pm_pair()
    for _ in range(12):
        pm.transport.send("BOGUS")
    wait_until(lambda: list(emu.status.errors)[-1:] == [-350], what="the emulator's queue overflow")
    errors = pm.errors()
    assert len(errors) == 10 and errors[-1] == (-350, "Queue overflow")
    pm.transport.send("BOGUS")
    pm.query("*CLS")
    assert pm.errors() == []


def test_overlong_line_and_invalid_character(pm_pair):
    emu, pm = pm_pair()
    pm.transport.send("SENS:CORR:WAV " + "1" * 600)
    assert pm.errors() == [(-363, "Input buffer overrun")]
    pm.transport.link.write(b"\xff\xfe\n")
    assert pm.errors() == [(-101, "Invalid character")]


def test_rst_restores_defaults(pm_pair):
    emu, pm = pm_pair()
    pm.configure(900.0, 8, 1e-3)
    pm.query("*RST")
    assert (pm.wavelength_nm, pm.averaging, pm.range_w) == (632.8, 1, None)


def test_source_failure_is_a_device_error_not_a_crash(pm_pair):
    emu, pm = pm_pair(source=lambda: float("nan"))
    with pytest.raises(DeviceError, match="-230"):
        pm.read()


def test_stalled_reply_timeout_is_named_and_bounded(pm_pair):
    emu, pm = pm_pair(timeout_s=0.1, retries=1)
    inject(emu, stall_prob=1.0)
    with pytest.raises(DeviceTimeout, match="pm100: timeout after 0.1 s waiting for :READ"):
        pm.read()
    assert emu.server.faults.counts["stall"] == 1 + 1  # 1 + 1 retry, bounded


def test_lost_setting_status_is_checked_not_resent(pm_pair):
    emu, pm = pm_pair(timeout_s=0.1, retries=3)
    inject(emu, stall_prob=0.3, seed=4)
    for wl in (500.0, 600.0, 700.0, 800.0, 900.0):
        try:
            pm.wavelength_nm = wl
        except DriverError:
            continue
        assert emu.wavelength_nm == wl
    assert emu.server.faults.counts["stall"] > 0


def test_corrupted_and_dropped_replies(pm_pair):
    emu, pm = pm_pair(retries=0, detector=QUIET)
    inject(emu, corrupt_prob=1.0)
    with pytest.raises(ProtocolError, match="pm100: garbled reply"):
        pm.read()
    inject(emu, corrupt_prob=0.5, seed=9)
    pm.transport.retries = 8
    assert all(r.range_w == 1e-5 for r in (pm.read() for _ in range(10)))
    pm.transport.retries = 0
    inject(emu, drop_prob=1.0, seed=1)
    caught = 0
    for _ in range(30):
        try:
            pm.read()
        except (ProtocolError, DeviceError):
            caught += 1
    assert caught > 0 and emu.server.faults.counts["drop"] == 30


def test_latency_and_disconnect(pm_pair):
    emu, pm = pm_pair(timeout_s=0.5)
    inject(emu, latency_s=0.05)
    t0 = time.monotonic()
    pm.read()
    assert time.monotonic() - t0 >= 0.05
    inject(emu, disconnect_after=1)
    pm.read()
    with pytest.raises(DriverError, match=r"pm100: serial port /dev/\S+ went away"):
        for _ in range(3):
            pm.read()


def test_a_reading_averaging_many_samples_is_waited_for_as_long_as_they_take(start_pair):
    # the manual: 1 sample takes approx. 3 ms; 400 of them (1.2 s) outlast the 1 s timeout_s,
    # which a reading's reply is given on top of that time (a second's slack under load),
    # never re-asked
    emu = Pm100Emulator(ConstantPower(2e-6), seed=3, clock=VirtualClock(1.0))
    emu, pm = start_pair(emu, Pm100, timeout_s=1.0, retries=0, name="pm100")
    pm.configure(wavelength_nm=632.8, averaging=400, range_w=None)
    assert pm.read().power_w == pytest.approx(2e-6, rel=0.05)
    assert pm.measure() == pytest.approx(2e-6, rel=0.05)
    assert pm.transport.timeout_s == 1.0 and pm.transport.resyncs == 0
