"""Ports held, not shared (drivers.port_lock), with real ptys and real processes: a second
holder in another process is refused naming the first's PID, and gets in once the first
releases; a pyserial client that opens with `exclusive=True` and gonio keep each other out;
the UUCP LCK file of a dead process is cleaned, a live one's refuses; a refused open leaves
the line as it was; a dead holder's LCK file is replaced only by the flock's holder, so two
processes never remove each other's; a VISA resource is held by a lock file; the serial
transport holds its port from before opening to close; a port this process holds for one
device is refused to another, naming it; the holder's command line shows base names; a lock
file that cannot be written is one error and holds nothing."""

from __future__ import annotations

import contextlib
import os
import select
import subprocess
import sys
import termios
from pathlib import Path

import pytest
from port_testkit import (
    ENV,
    HOLDER,
    child,
    needs_another_user,
    opens_as_another_user,
    said,
    tell,
    uucp_file,
)

from drivers import port_lock
from drivers.port_lock import PortInUse, hold, lock_dir
from drivers.serial_transport import SerialLineTransport

# a client that opens the port with pyserial's own exclusive lock (flock), as pymodbus does
PYSERIAL_EXCLUSIVE = """
import sys, serial
try:
    port = serial.Serial(sys.argv[1], exclusive=True)
except serial.SerialException as exc:
    print("refused:", exc, flush=True)
    sys.exit(0)
print("held", flush=True)
sys.stdin.readline()
"""


def test_a_second_holder_is_refused_naming_the_first_and_gets_in_once_it_releases(pty):
    _, path = pty
    with child(HOLDER, path) as first:
        assert said(first) == "held"
        with pytest.raises(PortInUse) as refused:
            hold(path, "pm100")
        assert refused.value.holder_pid == first.pid
        assert refused.value.port == path and refused.value.device == "pm100"
        message = str(refused.value)
        assert message.startswith(f"pm100: {path} is in use by process {first.pid} (")
        assert "\n" not in message and "-c import sys from drivers.port_lock" in message
        tell(first)
        assert said(first) == "released"  # still running: the release let go, not its end
        with hold(path, "pm100"):
            assert int(uucp_file(path).read_text()) == os.getpid()
    assert not uucp_file(path).exists()


def test_a_symlink_to_the_port_is_the_same_port(pty, tmp_path):
    _, path = pty
    alias = tmp_path / "usb-Thorlabs_PM100USB-if00"
    alias.symlink_to(path)
    with child(HOLDER, path) as first:
        assert said(first) == "held"
        with pytest.raises(PortInUse, match=f"^esp: {alias} \\({path}\\) is in use by process "
                                            f"{first.pid} ") as refused:
            hold(str(alias), "esp")
        assert refused.value.port == str(alias)


def test_pyserial_exclusive_clients_and_gonio_keep_each_other_out(pty):
    master, path = pty
    with hold(path, "esp"), child(PYSERIAL_EXCLUSIVE, path) as other:
        assert said(other).startswith("refused: [Errno 11] Could not exclusively lock port")
    uucp_file(path).unlink(missing_ok=True)
    with child(PYSERIAL_EXCLUSIVE, path) as other, open(path, "rb+", buffering=0) as port:
        assert said(other) == "held"
        before = termios.tcgetattr(port)  # as the holder set the line up
        with pytest.raises(PortInUse) as refused:  # no LCK file: the holder from /proc/locks
            hold(path, "esp")
        assert refused.value.holder_pid == other.pid
        assert termios.tcgetattr(port) == before
        assert select.select([master], [], [], 0)[0] == []  # nothing written to the line
    assert not uucp_file(path).exists()  # ours, taken before the flock refused, is gone


def test_a_stale_lck_file_of_a_dead_process_is_cleaned(pty):
    _, path = pty
    ended = subprocess.Popen([sys.executable, "-c", "pass"])
    ended.wait()
    uucp_file(path).write_text(f"{ended.pid:10d}\n")
    with hold(path, "esp"):
        assert uucp_file(path).read_text() == f"{os.getpid():10d}\n"  # HDB: ten-byte ASCII
    assert not uucp_file(path).exists()


def test_a_live_foreign_lck_file_refuses(pty):
    _, path = pty
    with child("import sys; sys.stdin.readline()") as other:
        uucp_file(path).write_text(f"{other.pid:10d}\n")
        with pytest.raises(PortInUse, match=f"is in use by process {other.pid}"):
            hold(path, "esp")
        assert uucp_file(path).read_text() == f"{other.pid:10d}\n"  # theirs, kept


def test_a_lck_file_that_names_no_process_refuses_naming_it(pty):
    _, path = pty
    uucp_file(path).write_text("")  # its writer may be between creating and writing it
    with pytest.raises(PortInUse, match=f"in use by another process \\(lock file "
                                        f"{uucp_file(path)}\\)$") as refused:
        hold(path, "esp")
    assert refused.value.holder_pid is None


def test_a_visa_resource_is_held_by_a_lock_file_with_the_holders_pid(tmp_path, monkeypatch):
    monkeypatch.setenv("GONIO_LOCK_DIR", str(tmp_path))
    resource = "TCPIP::127.0.0.1::5025::SOCKET"
    env = {**ENV, "GONIO_LOCK_DIR": str(tmp_path)}
    proc = subprocess.Popen([sys.executable, "-c", HOLDER, resource], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True, env=env)
    try:
        assert said(proc) == "held"
        assert lock_dir() == tmp_path
        [lock_file] = tmp_path.iterdir()
        assert lock_file.read_text() == f"{proc.pid}\n"
        with pytest.raises(PortInUse) as refused:  # the same resource, written otherwise
            hold("tcpip0::127.0.0.1::5025::socket", "meter")
        assert refused.value.holder_pid == proc.pid
        assert str(refused.value).startswith("meter: tcpip0::127.0.0.1::5025::socket is in "
                                             f"use by process {proc.pid} (")
        with hold("TCPIP0::127.0.0.1::5026::SOCKET", "other"):
            pass  # another port of the host is another resource
        tell(proc)
        assert said(proc) == "released"
        assert lock_file.read_text() == ""
        with hold(resource, "meter"):
            assert lock_file.read_text() == f"{os.getpid()}\n"
    finally:
        proc.stdin.close()
        proc.wait(timeout=30)


def test_an_asrl_resource_holds_its_device(pty):
    _, path = pty
    with child(HOLDER, f"ASRL{path}::INSTR") as first:
        assert said(first) == "held"
        with pytest.raises(PortInUse, match=f"process {first.pid}"):
            hold(path, "pm100")


def test_a_port_that_cannot_be_opened_is_the_transports_own_error(tmp_path):
    missing = str(tmp_path / "ttyUSB9")
    with pytest.raises(Exception, match="could not be opened") as failed:
        SerialLineTransport(missing, name="esp")
    assert not isinstance(failed.value, PortInUse)


@needs_another_user
def test_the_transport_holds_its_port_from_opening_to_close(pty):
    _, path = pty
    transport = SerialLineTransport(path, name="esp")
    try:
        assert int(uucp_file(path).read_text()) == os.getpid()
        # a pty is not opened for exclusive use (its flag would outlive a killed holder while
        # the far side keeps the master open): the locks keep others out
        # (test_port_exclusive.py: a serial port's TIOCEXCL)
        assert opens_as_another_user(path) == "opened"
        with pytest.raises(PortInUse):
            hold(path, "pm100")
    finally:
        transport.close()
    transport.close()  # idempotent
    assert not uucp_file(path).exists()
    assert opens_as_another_user(path) == "opened"  # the pty's exclusive flag is cleared
    with hold(path, "pm100"):
        pass


def test_a_stale_lck_file_is_replaced_only_by_the_flocks_holder(pty, monkeypatch):
    """Two processes find the same dead holder's LCK file: the one preempted after reading it
    (here: the other one holds the port in between) is refused by the flock and leaves the
    other's fresh LCK file in place."""
    _, path = pty
    ended = subprocess.Popen([sys.executable, "-c", "pass"])
    ended.wait()
    uucp_file(path).write_text(f"{ended.pid:10d}\n")
    check_alive = port_lock._alive
    with contextlib.ExitStack() as others:
        first: list[subprocess.Popen] = []

        def preempted_after_reading(pid: int) -> bool:
            alive = check_alive(pid)
            if pid == ended.pid and not first:  # the other process runs here, to the end
                first.append(others.enter_context(child(HOLDER, path)))
                assert said(first[0]) == "held"
            return alive

        monkeypatch.setattr(port_lock, "_alive", preempted_after_reading)
        with pytest.raises(PortInUse) as refused:
            hold(path, "esp")
        assert refused.value.holder_pid == first[0].pid
        assert uucp_file(path).read_text() == f"{first[0].pid:10d}\n"  # theirs, kept


def test_a_port_this_process_holds_is_refused_naming_the_device_that_has_it(pty):
    _, path = pty
    resource = f"ASRL{path}::INSTR"
    esp = SerialLineTransport(path, name="esp")
    try:
        with pytest.raises(PortInUse, match=f"^pm100: {resource} \\({path}\\) is in use: "
                                            "already opened by this gonio for device esp$"):
            SerialLineTransport(resource=resource, name="pm100")
    finally:
        esp.close()
    with hold(resource, "pm100"):
        assert int(uucp_file(path).read_text()) == os.getpid()


def test_the_holders_command_line_shows_base_names(pty, tmp_path):
    _, path = pty
    script = tmp_path / "hold_port.py"
    script.write_text(HOLDER)
    with subprocess.Popen([sys.executable, str(script), path], stdin=subprocess.PIPE,
                          stdout=subprocess.PIPE, text=True, env=ENV) as first:
        assert said(first) == "held"
        with pytest.raises(PortInUse) as refused:
            hold(path, "esp")
        first.stdin.close()
    assert str(refused.value) == (f"esp: {path} is in use by process {first.pid} "
                                  f"({Path(sys.executable).name} hold_port.py {Path(path).name})")


# holds argv[1] with no room to write the lock file's PID (a file-size limit of 0 bytes, as a
# full disk would refuse it), then with room again, in one process
HOLD_WITHOUT_ROOM = """
import resource, signal, sys
from drivers.base import DriverError
from drivers.port_lock import hold
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # the write fails with EFBIG instead
soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
resource.setrlimit(resource.RLIMIT_FSIZE, (0, hard))
try:
    hold(sys.argv[1], "meter")
except DriverError as exc:
    print(exc)
resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
hold(sys.argv[1], "meter").release()
print("held")
"""



def test_a_lock_file_that_cannot_be_written_is_one_error_and_leaves_the_resource_free(tmp_path):
    resource = "TCPIP0::127.0.0.1::5025::SOCKET"
    done = subprocess.run([sys.executable, "-c", HOLD_WITHOUT_ROOM, resource],
                          capture_output=True, text=True, timeout=30,
                          env={**ENV, "GONIO_LOCK_DIR": str(tmp_path)})
    assert done.returncode == 0, done.stderr
    [lock_file] = tmp_path.iterdir()
    assert done.stdout.splitlines() == [
        f"meter: cannot hold {resource}: File too large: {lock_file}",
        "held",  # the failed hold let its lock go
    ]
