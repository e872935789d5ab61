"""The PM100 emulator as each console and sensor head, over a real pty: *IDN? per model, the
front-panel commands only where the model has the panel, SYST:SENS:IDN? and the wavelength
range per head (a photodiode command with a thermal head is -241), and the measurement
settings of the manual's SENSe / CONFigure / MEASure lists for a power sensor: units, current
and power density, delta reference, attenuation, responsivity, beam, filter, line frequency."""

import math

import pytest

from sim.devices.photodiode import ConstantPower
from sim.devices.pm100 import Pm100Emulator

QUIET = {"read_noise_fraction": 0.0, "bandwidth_hz": 0.0, "dark_current_a": 0.0,
         "adc_bits": 32}


@pytest.mark.parametrize("model, display, clock, beeper", [
    ("PM100D", ("BRIG", "CONT"), True, True),
    ("PM100A", ("BRIG",), False, True),
    ("PM100USB", (), False, False),
    ("PM400", ("BRIG",), False, False),
])
def test_each_console_identifies_itself_and_has_its_panel(scpi, model, display, clock, beeper):
    emu, port = scpi(model=model)
    assert port.ask("*IDN?").startswith(f"Thorlabs,{model},P")
    expected = []
    for setting in ("BRIG", "CONT"):
        port.send(f"DISP:{setting} 0.25")
        if setting in display:
            assert port.ask(f"DISP:{setting}?") == "2.500000E-01"
        else:
            expected.append(-113)
    port.send("SYST:DATE 2024, 2, 29")
    if clock:
        assert port.ask("SYST:DATE?") == "2024,2,29"
    else:
        expected.append(-113)
    port.send("SYST:BEEP;:SYST:BEEP:STAT OFF")
    if beeper:
        assert port.ask("SYST:BEEP:STAT?") == "0" and emu.panel.beeps == 1
    else:
        expected += [-113, -113]
    assert port.ask('CAL:STR?').startswith('"') and port.errors() == expected


def test_line_frequency_is_50_or_60(scpi):
    emu, port = scpi(model="PM100USB")
    port.send("SYST:LFR 60")
    assert port.ask("SYST:LFR?") == "60"
    port.send("SYST:LFR 55;:SYST:LFR 50.5")
    assert port.errors() == [-224, -222] and port.ask("SYST:LFR?") == "60"
    port.send("*RST")
    assert port.ask("SYST:LFR?") == "60"  # a system setting, not reset


def test_clock_refuses_a_day_the_month_lacks(scpi):
    emu, port = scpi(model="PM100D", wall=lambda: 1.7e9)
    port.send("SYST:DATE 2023, 2, 29")
    assert port.errors() == [-222]


@pytest.mark.parametrize("head, kind, low, high", [
    ("S120C", "1", 400.0, 1100.0), ("S121C", "1", 400.0, 1100.0),
    ("S130C", "1", 400.0, 1100.0), ("S122C", "1", 700.0, 1800.0),
    ("S302C", "2", 190.0, 25000.0),
])
def test_each_head_reports_itself_and_bounds_the_wavelength(scpi, head, kind, low, high):
    emu, port = scpi(sensor=head)
    fields = port.ask("SYST:SENS:IDN?").split(",")
    assert (fields[0], fields[3]) == (head, kind)
    assert port.ask("SENS:CORR:WAV? MIN;WAV? MAX") == f"{low:.6E};{high:.6E}"
    lo, hi = float(port.ask("SENS:CORR:WAV? MIN")), float(port.ask("SENS:CORR:WAV? MAX"))
    port.send(f"SENS:CORR:WAV {lo - 1:g};:SENS:CORR:WAV {hi + 1:g}")
    assert port.errors() == [-222, -222]
    assert low <= float(port.ask("SENS:CORR:WAV?")) <= high  # powered up inside the range


def test_a_thermal_head_refuses_photodiode_commands(scpi):
    emu, port = scpi(sensor="S302C")
    assert int(port.ask("SYST:SENS:IDN?").split(",")[5]) & 64  # tau settable
    port.send("SENS:CORR:POW:PDI:RESP?;:MEAS:CURR?;:INP:PDI:FILT:LPAS:STAT 1")
    assert port.errors() == [-241, -241, -241]
    assert float(port.ask("MEAS:POW?")) > 0


def test_an_unknown_model_or_head_is_refused():
    with pytest.raises(ValueError, match="no console model 'PM999'.*PM100USB"):
        Pm100Emulator(ConstantPower(1e-6), model="PM999")
    with pytest.raises(ValueError, match="no sensor head 'S999C'.*S122C"):
        Pm100Emulator(ConstantPower(1e-6), sensor="S999C")
    with pytest.raises(ValueError, match="1550.*S120C's range 400-1100 nm"):
        Pm100Emulator(ConstantPower(1e-6), sensor="S120C", wavelength_nm=1550)


def test_power_in_watts_and_dbm(scpi):
    emu, port = scpi(power_w=1e-3, detector=QUIET)
    assert float(port.ask("MEAS:POW?")) == pytest.approx(1e-3, rel=1e-6)
    port.send("SENS:POW:UNIT DBM")
    assert port.ask("SENS:POW:UNIT?") == "DBM"
    assert float(port.ask("MEAS:POW?")) == pytest.approx(0.0, abs=1e-5)
    port.send("SENS:POW:UNIT W;:SENS:POW:UNIT VOLT")
    assert port.errors() == [-224] and port.ask("POW:UNIT?") == "W"


def test_current_and_power_density(scpi):
    emu, port = scpi(power_w=1e-4, detector=QUIET)
    response = float(port.ask("SENS:CORR:POW:PDI:RESP?"))
    assert port.ask("CONF:CURR;:CONF?") == "CURR"
    assert float(port.ask("READ?")) == pytest.approx(1e-4 * response, rel=1e-6)
    port.send("SENS:CORR:BEAM 2 mm")
    assert float(port.ask("MEAS:PDEN?")) == pytest.approx(1e-4 / (math.pi * 0.1**2), rel=1e-6)
    assert port.ask("CONF?") == "PDEN" and port.errors() == []


def test_delta_reference_attenuation_and_responsivity(scpi):
    emu, port = scpi(power_w=1e-4, detector=QUIET)
    port.send("SENS:POW:REF 4E-5;:SENS:POW:REF:STAT ON")
    assert float(port.ask("MEAS:POW?")) == pytest.approx(6e-5, rel=1e-6)
    port.send("SENS:POW:REF:STAT OFF;:SENS:CORR:LOSS:INP:MAGN 10")
    assert float(port.ask("MEAS:POW?")) == pytest.approx(1e-3, rel=1e-6)
    port.send("SENS:CORR:LOSS 0")
    response = float(port.ask("SENS:CORR:POW:RESP? DEF"))
    port.send(f"SENS:CORR:POW:PDI:RESP {response * 2}")
    assert float(port.ask("MEAS:POW?")) == pytest.approx(5e-5, rel=1e-6)
    port.send("SENS:CORR:WAV 800")  # the head's responsivity at the new wavelength
    assert float(port.ask("MEAS:POW?")) == pytest.approx(1e-4, rel=1e-6)
    port.send("SENS:CORR:POW:RESP 20;:SENS:CORR:LOSS 61")
    assert port.errors() == [-222, -222]


def test_filter_beam_and_averaging_limits(scpi):
    emu, port = scpi()
    port.send("INP:PDI:FILT:LPAS:STAT ON")
    assert port.ask("INPUT:PDIODE:FILTER:LPASS:STATE?") == "1"
    assert port.ask("SENS:CORR:BEAM? DEF") == "9.500000E+00"
    assert port.ask("SENS:AVER:COUN? MIN;COUN? MAX") == "1;10000"
    port.send("SENS:CORR:WAV DEF;:SENS:CORR:BEAM 0;:SENS:AVER:COUN 10001")
    assert port.errors() == [-224, -222, -222]
    port.send("*RST")
    assert port.ask("INP:PDI:FILT:LPAS:STAT?;:SENS:CORR:BEAM?") == "0;9.500000E+00"


def test_reset_returns_the_measurement_settings_to_their_defaults(scpi):
    emu, port = scpi()
    port.send("SENS:POW:REF 1E-6;REF:STAT ON;:SENS:POW:UNIT DBM;:SENS:CURR:REF:STAT 1;:CONF:CURR")
    port.send("SENS:CORR:LOSS 3;:SENS:CORR:POW:RESP 0.2;:SENS:POW:RANG:AUTO OFF")
    port.send("*RST")
    assert port.errors() == []
    assert port.ask("SENS:POW:REF?;REF:STAT?;:SENS:POW:UNIT?;:SENS:CURR:REF:STAT?;:CONF?") == (
        "0.000000E+00;0;W;0;POW")
    assert port.ask("SENS:CORR:LOSS?;:SENS:POW:RANG:AUTO?") == "0.000000E+00;1"
    assert port.ask("SENS:CORR:POW:RESP?") == port.ask("SENS:CORR:POW:RESP? DEF")
    port.send("SENS:POW:REF:STAT ON")
    assert port.ask("SENS:POW:REF:STAT?") == "1" and port.errors() == []
