"""A Modbus request a signal cuts short, over RTU on a pty and TCP: its late reply never
answers the next read (RTU: the echo first; TCP: a new connection)."""

import signal

import pytest
from waiting import wait_until

from sim.devices.faults import FaultInjector, FaultSpec


class Interrupted(Exception):
    """What the test's SIGALRM handler raises while a reply is awaited."""


def interrupt(signum, frame):
    raise Interrupted


@pytest.mark.parametrize("transport", ["tcp", "rtu"])
def test_a_read_a_signal_cut_short_does_not_answer_the_next(rig, transport):
    r = rig(transport, stage_faults={"latency_s": 0.3}, reply_s=1.0, read_retries=0)
    old_handler = signal.signal(signal.SIGALRM, interrupt)
    try:
        signal.setitimer(signal.ITIMER_REAL, 0.1)
        with pytest.raises(Interrupted):
            r.stage.motion()  # velocity and acceleration: four registers, as the limits
    finally:
        signal.signal(signal.SIGALRM, old_handler)
    r.stage_emu.faults = FaultInjector(FaultSpec())
    assert r.stage.limits() == (-95.0, 95.0)  # not the late (20, 80)
    assert r.stage.link.in_step
    # the late reply goes out (on TCP, to the closed connection) before the stop
    wait_until(lambda: r.server.late_replies == 1 and not r.server.late_pending,
               what="the late reply")
