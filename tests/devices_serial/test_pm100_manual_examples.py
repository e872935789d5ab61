"""The PM100D / PM100USB / PM400 manuals' own SCPI examples, sent byte for byte over a real pty
to the emulator: the common-command message, the wavelength queries with MIN / MAX, the
compound messages of the "Command Separators" section (with and without the colon), the
letter-case and short / long form rules, the optional [:DC] node, MIN / MAX / DEF parameters,
the clock's three-parameter command, *IDN? as real units answer it and SYST:SENS:IDN? in the
manual's format, *TST?, *OPC and *WAI as the PM100 manual describes them."""

import re

import pytest

GERMANIUM = {"sensor": "S122C"}  # a head that takes the manual's 1550 nm and 1310 nm


def test_common_commands_in_one_message(scpi):
    """'"*RST; *CLS; *ESE 32; *OPC?"': every unit runs, *OPC? answers 1."""
    emu, port = scpi()
    assert port.ask("*RST; *CLS; *ESE 32; *OPC?") == "1"
    assert port.ask("*ESE?") == "32" and port.errors() == []


def test_setting_and_querying_the_operating_wavelength(scpi):
    """'"CORR:WAVE 1550"', '"CORR:WAVE?"', '"CORR:WAVE? MIN"', '"CORR:WAVE? MAX"'."""
    emu, port = scpi(**GERMANIUM)
    port.send("CORR:WAVE 1550")
    assert port.ask("CORR:WAVE?") == "1.550000E+03"
    assert port.ask("CORR:WAVE? MIN") == "7.000000E+02"
    assert port.ask("CORR:WAVE? MAX") == "1.800000E+03"
    assert emu.wavelength_nm == 1550.0 and port.errors() == []


def test_a_semicolon_continues_the_subsystem(scpi):
    """'"CORR:BEAM 1; WAVE 1310" ... is the same as sending the two commands'."""
    emu, port = scpi(**GERMANIUM)
    port.send("CORR:BEAM 1; WAVE 1310")
    together = port.ask("CORR:BEAM?;:CORR:WAVE?")
    port.send("*RST")
    port.send("CORR:BEAM 1")
    port.send("CORR:WAVE 1310")
    assert port.ask("CORR:BEAM?;:CORR:WAVE?") == together == "1.000000E+00;1.310000E+03"
    assert port.errors() == []


def test_another_subsystem_needs_colon_and_semicolon(scpi):
    """'"CORR:BEAM 1;:AVER 300"' works; 'an error is generated if you do not use both the
    colon and semicolon'."""
    emu, port = scpi()
    port.send("CORR:BEAM 1;:AVER 300")
    assert port.ask("AVER?") == "300" and port.errors() == []
    port.send("CORR:BEAM 2;AVER 20")
    assert port.errors() == [-113]
    assert port.ask("CORR:BEAM?;:AVER?") == "2.000000E+00;300"  # the first unit ran


@pytest.mark.parametrize("header", ["CURRENT:RANGE?", "current:range?", "Current:Range?",
                                    "CURR:RANG?", "CURR:DC:RANG?"])
def test_short_long_and_any_case_forms(scpi, header):
    """'CURR and CURRENT are both acceptable ... CURRENT, current, and Current are all
    acceptable'; '[:DC] can be omitted'."""
    emu, port = scpi()
    port.send("CURR:DC:RANG 50E-6")
    assert float(port.ask(header)) >= 50e-6
    assert port.errors() == []


@pytest.mark.parametrize("header", ["CUR:RANG?", "CURREN:RANG?"])
def test_other_forms_generate_an_error(scpi, header):
    """'Other forms, such as CUR and CURREN, will generate an error.'"""
    emu, port = scpi()
    port.send(header)
    assert port.errors() == [-113]


def test_the_current_range_example_with_and_without_the_optional_node(scpi):
    """'"CURR:DC:RANG 50E-6"' and its shortened form '"CURR:RANG 50E-6"' set the same range."""
    emu, port = scpi()
    port.send("CURR:DC:RANG 50E-6")
    first = port.ask("CURR:RANG?")
    port.send("CURR:RANG:AUTO ON")
    port.send("CURR:RANG 50E-6")
    assert port.ask("CURR:DC:RANG?") == first and port.ask("CURR:RANG:AUTO?") == "0"
    assert port.errors() == []


def test_min_max_def_for_a_numeric_parameter(scpi):
    """'POWer:REFerence {MINimum|MAXimum|DEFault|<numeric_value>[W]}' and its query."""
    emu, port = scpi()
    top = port.ask("POW:RANG? MAX")
    assert port.ask("POW:REF? MIN;REF? DEF") == "0.000000E+00;0.000000E+00"
    assert port.ask("POWer:REFerence? MAXimum") == top
    port.send("POWer:REFerence MAXimum")
    assert port.ask("POW:REF?") == top
    port.send("POW:REF 1.5 uW")
    assert port.ask("POW:REF?") == "1.500000E-06"
    port.send("POW:REF DEF")
    assert port.ask("POW:REF?") == "0.000000E+00" and port.errors() == []


def test_clock_command_takes_three_parameters(scpi):
    """'"SYST:TIME 10, 34, 48"' (PM100D): the clock then runs from 10:34:48."""
    now = [1.7e9]
    emu, port = scpi(model="PM100D", wall=lambda: now[0])
    port.send("SYST:TIME 10, 34, 48")
    assert port.ask("SYST:TIME?") == "10,34,48"
    now[0] += 75.0
    assert port.ask("SYST:TIME?") == "10,36,3"
    port.send("SYST:TIME 10, 34")
    port.send("SYST:TIME 24, 0, 0")
    assert port.errors() == [-109, -222]


#: *IDN? answers of real units, as logs in public code give them (a MATLAB setup routine's
#: comments: PM100USB, PM100A; a PyVISA script's header: PM100D)
REAL_IDN = ("Thorlabs,PM100USB,P2004081,1.4.0", "Thorlabs,PM100A,P1003352,2.4.0",
            "Thorlabs,PM100D,P0027168,2.7.0")


@pytest.mark.parametrize("real", REAL_IDN)
def test_identification_as_real_units_answer(scpi, real):
    """'THORLABS,MMM,SSS,X.X.X', where MMM is the model code, SSS the serial number, X.X.X the
    firmware revision: real units write the maker in mixed case (REAL_IDN), their serial
    numbers a letter and seven digits, the first digit the model's series."""
    maker, model, serial, firmware = real.split(",")
    emu, port = scpi(model=model)
    answer = port.ask("*IDN?").split(",")
    assert answer[:2] == [maker, model] and len(answer) == 4
    assert re.fullmatch(r"P\d{7}", answer[2]) and answer[2][:2] == serial[:2]
    assert re.fullmatch(r"\d+\.\d+\.\d+", answer[3]) and re.fullmatch(r"\d+\.\d+\.\d+", firmware)


def test_sensor_information_fields(scpi):
    """'<name>,<sn>,<cal_msg>,<type>,<subtype>,<flags>': is power sensor 1, response settable
    16, wavelength settable 32."""
    emu, port = scpi(sensor="S120C")
    name, serial, calibration, kind, subtype, flags = port.ask("SYST:SENS:IDN?").split(",")
    assert (name, kind) == ("S120C", "1") and serial and calibration
    assert int(flags) & (1 | 16 | 32) == 1 | 16 | 32 and not int(flags) & 2


def test_self_test_operation_complete_and_wait(scpi):
    """*TST? answers 0 (passed); *OPC sets the OPC bit of the Standard Event Status Register;
    *WAI has no effect."""
    emu, port = scpi()
    assert port.ask("*TST?") == "0"
    assert port.ask("*CLS;*OPC;*WAI;*ESR?") == "1"
    assert port.ask("*ESR?") == "0" and port.errors() == []


def test_zero_adjustment_commands(scpi):
    """The manual's SENSe tree: CORRection:COLLect:ZERO [:INITiate], :ABORt, :STATe?,
    :MAGNitude?."""
    emu, port = scpi(power_w=0.0)
    port.send("SENS:CORR:COLL:ZERO:INIT")
    assert port.ask("SENS:CORR:COLL:ZERO:STAT?") == "0"
    assert float(port.ask("SENS:CORR:COLL:ZERO:MAGN?")) > 0  # the dark current's offset
    port.send("SENS:CORR:COLL:ZERO:ABOR;:SENS:CORR:COLL:ZERO")
    assert port.errors() == []
