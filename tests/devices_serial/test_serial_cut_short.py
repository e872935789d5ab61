"""An exchange a signal cuts short (Ctrl-C, SIGTERM mid-reply), over a real pty: the line is
left out of step, not broken, and the late reply never answers the next query."""

import signal

import pytest

from sim.devices.faults import FaultInjector, FaultSpec


class CutShort(Exception):
    """Raised by the test's SIGALRM handler, in the middle of an exchange."""


def cut_short(signum, frame):
    raise CutShort


def test_a_reply_a_signal_cut_short_does_not_answer_the_next_query(pm_pair):
    emu, pm = pm_pair(timeout_s=1.0, retries=0)  # no retry to hide a misread reply
    emu.server.faults = FaultInjector(FaultSpec(latency_s=0.3))
    previous = signal.signal(signal.SIGALRM, cut_short)
    try:
        signal.setitimer(signal.ITIMER_REAL, 0.1)
        with pytest.raises(CutShort):
            pm.query("*IDN?")  # its reply comes 0.2 s after the wait was cut
    finally:
        signal.signal(signal.SIGALRM, previous)
    assert not pm.transport.in_step
    emu.server.faults = FaultInjector(FaultSpec())
    assert pm.wavelength_nm == 632.8  # not the late *IDN? text, which would be garbled
    assert pm.transport.in_step and pm.transport.resyncs == 1
