"""Exclusive opens (TIOCEXCL) of held ports, as an unprivileged user sees them (root's opens
pass the flag): a serial port is opened for exclusive use while held, whether a port or a VISA
ASRL resource names it, and released with the hold; a pseudo-terminal is not (its flag would
outlive a killed holder while the far side keeps the master open), so a holder killed with
SIGKILL leaves it free; and a tty another program left exclusive is refused saying so.

A pty opened through a device node of the controlling terminal (/dev/tty's, made in the test's
own folder so that no other test shares its locks) stands for a serial port here: it is a tty
that is no pty slave by its device number, and its flag is the pty's, which the test reads."""

from __future__ import annotations

import errno
import fcntl
import os
import signal
import stat
import termios

import pytest
from port_testkit import (
    TRY_HOLD,
    as_another_user,
    child,
    holding,
    needs_another_user,
    opens_as_another_user,
    said,
)
from port_testkit import tell as release

pytestmark = needs_another_user
CONTROLLING_TERMINAL = (5, 0)  # /dev/tty's device number

# opens argv[1] (a pty) as its controlling terminal, then holds the serial transport on argv[2]
# (a node of the controlling terminal) as argv[3] says ("port" or "resource")
SERIAL_PORT_HOLDER = holding("""
import os
from drivers.serial_transport import SerialLineTransport
terminal = os.open(sys.argv[1], os.O_RDWR)  # a new session's first tty: its controlling one
node = sys.argv[2]
kind = {"port": {"port": node}, "resource": {"resource": f"ASRL{node}::INSTR"}}
transport = SerialLineTransport(name="pm100", **kind[sys.argv[3]])""", "transport.close()")
# holds argv[1] with the serial transport (to be killed)
TRANSPORT_HOLDER = holding("""
from drivers.serial_transport import SerialLineTransport
transport = SerialLineTransport(sys.argv[1], name="esp")""", "transport.close()")


@pytest.fixture
def terminal_node(tmp_path) -> str:
    """A device node of the controlling terminal (/dev/tty's major and minor)."""
    node = tmp_path / "tty"
    try:
        os.mknod(node, stat.S_IFCHR | 0o600, os.makedev(*CONTROLLING_TERMINAL))
    except PermissionError:
        pytest.skip("no device node may be made here (not root)")
    return str(node)


@pytest.mark.parametrize("given", ["port", "resource"])
def test_a_held_serial_port_is_opened_for_exclusive_use_until_release(pty, terminal_node,
                                                                       given):
    _, path = pty
    with child(SERIAL_PORT_HOLDER, path, terminal_node, given,
               start_new_session=True) as holder:
        assert said(holder) == "held"
        assert opens_as_another_user(path) == str(errno.EBUSY)
        release(holder)
        assert said(holder) == "released"
        assert opens_as_another_user(path) == "opened"


def test_a_pty_stays_free_to_others_when_its_holder_is_killed(pty):
    _, path = pty
    with child(TRANSPORT_HOLDER, path) as holder:
        assert said(holder) == "held"
        holder.send_signal(signal.SIGKILL)
        holder.wait()
    assert opens_as_another_user(path) == "opened"
    assert as_another_user(TRY_HOLD, path) == "held"


def test_a_tty_left_exclusive_by_a_program_is_refused_saying_so(pty):
    _, path = pty
    left = os.open(path, os.O_RDWR | os.O_NOCTTY)
    fcntl.ioctl(left, termios.TIOCEXCL)  # a program's, closed without clearing it
    os.close(left)
    assert as_another_user(TRY_HOLD, path) == (
        f"x: {path} is in use: opened for exclusive use by a process that did not release "
        f"it (no lock names it); end the program that has it open (fuser -v {path}) or unplug "
        "and replug the port")
