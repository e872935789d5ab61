"""A setting whose status is lost is settled by reading it back, by the rule declared with it,
over a real pty with the emulators' faults: the command is never sent twice, a read-back that
is not the requested value is an error, and one that is (to the reply's precision) is not."""

import pytest
from reply_faults import StallNext, spy_lines

from drivers.base import DeviceTimeout, DriverError


def test_a_fixed_range_never_sent_is_not_taken_for_the_one_asked(pm_pair):
    emu, pm = pm_pair(timeout_s=0.1)
    pm.range_w = 1e-6
    emu.server.faults = StallNext(2)
    with pytest.raises(DeviceTimeout):
        pm.transport.exchange(":SENS:POW:RANG?")  # lost: the line is out of step
    # the sync query before the range command is lost too, so the command is never written;
    # the read-back then finds the old fixed range, which is not the one asked for
    with pytest.raises(DriverError, match=r"':SENS:POW:RANG 1.000000E-04' not confirmed"):
        pm.range_w = 1e-4
    assert emu.range_w == 1e-6 and not emu.autorange
    assert pm.range_w == 1e-6


def test_a_fixed_range_whose_status_is_lost_is_confirmed_by_its_read_back(pm_pair):
    emu, pm = pm_pair(timeout_s=0.1)
    seen = spy_lines(emu)
    emu.server.faults = StallNext(1)
    pm.range_w = 1e-4  # taken; its status lost
    assert emu.range_w == 1e-4 and pm.range_w == 1e-4
    assert [line for line in seen if "RANG 1" in line] == [
        ":SENS:POW:RANG 1.000000E-04;:SYST:ERR?"]  # sent once


def test_autorange_whose_status_is_lost_is_confirmed_by_its_read_back(pm_pair):
    emu, pm = pm_pair(timeout_s=0.1)
    pm.range_w = 1e-6
    emu.server.faults = StallNext(1)
    pm.range_w = None
    assert emu.autorange and pm.range_w is None


def test_a_rate_set_finer_than_the_reply_shows_is_confirmed(esp_pair):
    # VA 12.345678 is read back as 12.34568 (five decimals): the same value to the precision
    # of the reply, so a lost status is settled, not reported as a refused setting
    emu, ctl = esp_pair(timeout_s=0.1)
    axis = ctl.axis(1)
    emu.server.faults = StallNext(1)
    axis.speed_deg_s = 12.345678
    assert emu.axes[1].motion.speed == 12.345678
    assert axis.speed_deg_s == 12.34568
    assert emu.received["VA"] == 1


def test_a_rate_the_controller_did_not_take_is_reported(esp_pair):
    emu, ctl = esp_pair(timeout_s=0.1)
    axis = ctl.axis(1)
    axis.speed_deg_s = 10.0
    emu.server.faults = StallNext(2)
    with pytest.raises(DeviceTimeout):
        ctl.transport.exchange("1VA?")  # lost: the line is out of step
    with pytest.raises(DriverError, match=r"'1VA12.5' not confirmed"):
        axis.speed_deg_s = 12.5  # its sync query lost: never written
    assert emu.axes[1].motion.speed == 10.0 and emu.received["VA"] == 1
