"""The PM100 emulator's status reporting over a real pty, as IEEE 488.2 and SCPI define it with
the bits Thorlabs' TLPM.h gives the PM100 family: the Standard Event Status Register (error
classes, OPC, power-on) and its enable, the status byte's summaries (EAV, QUES, MAV, ESB,
OPER, MSS) and SRE, the OPERation / QUEStionable / MEASurement / AUXiliary groups with
condition, transition filters, latched events and enable, STATus:PRESet, *CLS, and *RST
leaving the status alone."""

import pytest

QUIET = {"read_noise_fraction": 0.0, "bandwidth_hz": 0.0, "dark_current_a": 0.0}
OPER_RANG, OPER_MEAS, OPER_CORR, OPER_SENS, OPER_DATA = 4, 16, 128, 256, 512
QUES_POW = 8
STB_EAV, STB_QUES, STB_MAV, STB_ESB, STB_MSS, STB_OPER = 4, 8, 16, 32, 64, 128


def test_power_on_error_classes_and_the_event_status_enable(scpi):
    emu, port = scpi()
    assert port.ask("*ESR?") == "128"  # power on
    assert port.ask("*ESR?") == "0"  # cleared by reading
    port.send("SENS:BOGUS 1")  # -113: command error
    port.send("SENS:CORR:WAV 5000")  # -222: execution error
    assert port.ask("*ESR?") == str(32 + 16)
    assert port.errors() == [-113, -222]
    port.send("*ESE 16")
    port.send("SENS:AVER:COUN 0")
    assert int(port.ask("*STB?")) & STB_ESB  # an enabled event is latched
    assert port.ask("*ESR?;*ESE?") == "16;16"
    assert int(port.ask("*STB?")) & STB_ESB == 0


def test_status_byte_summaries_and_service_request(scpi):
    emu, port = scpi()
    assert int(port.ask("*STB?")) == 0
    port.send("NO:SUCH:HEADER")
    assert int(port.ask("*STB?")) == STB_EAV  # the error queue is not empty
    assert int(port.ask("*IDN?;*STB?").split(";")[1]) == STB_EAV | STB_MAV  # an answer waits
    port.send("*SRE 4")
    assert int(port.ask("*STB?")) == STB_EAV | STB_MSS
    assert port.ask("*SRE?") == "4"
    port.send("*SRE 255")
    assert port.ask("*SRE?") == "191"  # bit 6 of the SRE is ignored
    port.errors()
    assert int(port.ask("*STB?")) == 0


def test_operation_events_of_a_measurement(scpi):
    emu, port = scpi()
    assert port.ask("STAT:OPER:COND?") == str(OPER_SENS)  # a head is connected
    assert port.ask("STAT:OPER?") == "0"
    port.ask("READ?")
    assert int(port.ask("STAT:OPER:COND?")) == OPER_SENS | OPER_DATA
    events = int(port.ask("STAT:OPER:EVEN?"))
    assert events & (OPER_MEAS | OPER_DATA) == OPER_MEAS | OPER_DATA
    assert events & OPER_RANG  # autorange left the top range
    assert port.ask("STATUS:OPERATION:EVENT?") == "0"  # read and cleared
    port.send("ABOR")
    assert port.ask("STAT:OPER:COND?") == str(OPER_SENS)
    port.send("FETC?")
    assert port.errors() == [-230]


def test_transition_filters_decide_which_edges_latch(scpi):
    emu, port = scpi()
    port.send("STAT:OPER:PTR 0;NTR 512")  # only a falling data-ready latches
    port.send("INIT")
    assert port.ask("STAT:OPER?") == "0"
    port.send("CONF:POW")  # the stored reading goes: data ready falls
    assert port.ask("STAT:OPER?") == str(OPER_DATA)
    assert port.ask("STAT:OPER:PTR?;NTR?") == "0;512"
    port.send("STAT:PRES")
    assert port.ask("STAT:OPER:PTR?;NTR?;ENAB?") == "32767;0;0"


def test_zeroing_latches_the_correction_bit(scpi):
    emu, port = scpi(power_w=0.0)
    port.send("SENS:CORR:COLL:ZERO")
    assert int(port.ask("STAT:OPER?")) & OPER_CORR
    assert not int(port.ask("STAT:OPER:COND?")) & OPER_CORR  # done at once


def test_questionable_power_over_range_and_its_summary(scpi):
    emu, port = scpi(power_w=2e-5, detector=QUIET)
    port.send("SENS:POW:RANG 1E-6;:STAT:QUES:ENAB 8")  # a fixed range far below the light
    port.ask("READ?")
    assert port.ask("STAT:QUES:COND?") == str(QUES_POW)
    assert int(port.ask("*STB?")) & STB_QUES
    assert port.ask("STAT:QUES?") == str(QUES_POW)
    port.send("SENS:POW:RANG:AUTO 1")
    port.ask("READ?")
    assert port.ask("STAT:QUES:COND?") == "0"
    assert int(port.ask("*STB?")) & STB_QUES == 0


def test_operation_summary_and_master_summary(scpi):
    emu, port = scpi()
    port.send("STAT:OPER:ENAB 512;:*SRE 128")
    port.ask("READ?")
    assert int(port.ask("*STB?")) == STB_OPER | STB_MSS
    port.ask("STAT:OPER?")
    assert int(port.ask("*STB?")) == 0


@pytest.mark.parametrize("group", ["OPER", "QUES", "MEAS", "AUX"])
def test_every_register_group_takes_its_masks(scpi, group):
    emu, port = scpi()
    port.send(f"STAT:{group}:ENAB #H00FF;PTR #B101;NTR #Q17")
    assert port.ask(f"STAT:{group}:ENAB?;PTR?;NTR?") == "255;5;15"
    port.send(f"STAT:{group}:ENAB 65535")
    assert port.ask(f"STAT:{group}:ENAB?") == "32767"  # bit 15 is always 0
    port.send(f"STAT:{group}:ENAB 65536;:STAT:{group}:PTR #H1G;:STAT:{group}:COND 1")
    assert port.errors() == [-222, -104, -113]  # over 16 bits, no hex digit, query only
    assert port.ask(f"STAT:{group}:COND?;EVEN?").count(";") == 1


def test_clear_status_and_reset(scpi):
    emu, port = scpi()
    port.send("*ESE 255;*SRE 32;:STAT:OPER:ENAB 16;:SENS:AVER:COUN 8")
    port.send("BOGUS")
    port.ask("READ?")
    port.send("*RST")  # settings to defaults; the status data stay
    assert port.ask("SENS:AVER:COUN?") == "1"
    assert port.ask("*ESE?;*SRE?;:STAT:OPER:ENAB?") == "255;32;16"
    assert int(port.ask("*STB?")) & STB_EAV
    port.send("*CLS")  # events and the error queue cleared, enables kept
    assert port.ask("*ESR?;:STAT:OPER?;:SYST:ERR:COUN?") == "0;0;0"
    assert port.ask("*ESE?;*SRE?;:STAT:OPER:ENAB?") == "255;32;16"


def test_error_count_and_scpi_version(scpi):
    emu, port = scpi()
    port.send("A;B;C")
    assert port.ask("SYST:ERR:COUN?") == "3"
    assert port.ask("SYST:VERS?") == "1999.0"
    assert port.errors() == [-113, -113, -113]
    assert port.ask("SYST:ERR:COUN?") == "0"
