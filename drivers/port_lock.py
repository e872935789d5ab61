"""Ports held for a run: one process at a time on a serial port or an instrument resource.

`hold(endpoint, device)` is taken before a transport opens its port, so that a port another
process holds is refused (`PortInUse`, naming the port and the holder) before the refused
process touches the line: no termios change, no DTR toggle, no byte. What an endpoint names
comes from drivers.port_identity (one device written two ways is one port). What holds it:

- a device file (symlinks such as /dev/serial/by-id/... resolved; a VISA ASRL resource names
  one too), by the platform's conventions on Linux: the UUCP / FHS lock file `LCK..<name>` in
  /run/lock (or /var/lock), a live holder's honoured; and `flock(LOCK_EX | LOCK_NB)` on a
  descriptor of the device (the lock pyserial's `exclusive=True`, picocom and others take;
  its holder's PID from /proc/locks). Only the flock's holder removes a dead process's LCK
  file and writes ours (where the directory lets us), so two processes never remove each
  other's. Once the transport has opened the port, `HeldPort.exclusive()` sets TIOCEXCL on a
  serial port (further opens of the tty fail with EBUSY, root's excepted), cleared on
  release; not on a pseudo-terminal, whose flag outlives its holder while the far side keeps
  the master open.
- anything else (a VISA resource such as `TCPIP0::host::5025::SOCKET`, a pyserial URL): an
  flock'd file named from the resource's canonical name in the gonio lock directory
  (`lock_dir`), our PID written in it.

The flocks end with the process however it ends; a LCK file a killed process left names a
dead PID, and the next holder removes it. A port this process already holds for another
device is refused naming that device.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import stat
import termios
from pathlib import Path
from urllib.parse import quote

from drivers.base import DriverError
from drivers.byte_link import is_pty
from drivers.port_identity import UnsettledPort, port_identity

UUCP_LOCK_DIRS = (Path("/run/lock"), Path("/var/lock"))  # FHS, then its older name
LOCK_DIR_ENV = "GONIO_LOCK_DIR"
FALLBACK_LOCK_DIR = Path("/tmp/gonio-locks")
SHARED_DIR_MODE = 0o1777  # every user's gonio writes there; none removes another's file
COMMAND_SHOWN = 80  # characters of the holder's command line in the message
# how the device is opened to be locked: no controlling tty, no wait for carrier
DEVICE_OPEN = os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK

_held_here: dict[Path | str, str] = {}  # what this process holds: port -> device


class PortInUse(DriverError):
    """Another process holds the port (as configured; `device_file` what it resolves to):
    `holder_pid` names it (None where the platform does not tell); the message is one line
    naming the port and the holder (`holder` says it otherwise), `how` saying more of the
    lock that refused."""

    def __init__(self, device: str, port: str, holder_pid: int | None, how: str = "",
                 device_file: Path | None = None, *, holder: str | None = None):
        self.device, self.port, self.holder_pid = device, port, holder_pid
        resolved = f" ({device_file})" if device_file and str(device_file) != port else ""
        holder = holder or f" by {_holder(holder_pid)}"
        super().__init__(f"{device}: {port}{resolved} is in use{holder}{how}")


class Unholdable(DriverError):
    """A VISA resource whose port cannot be held, so it is not opened either: it names no
    device file, or one that cannot be opened (`cause`, the error that says why)."""

    def __init__(self, device: str, endpoint: str, cause: Exception):
        self.cause = cause
        super().__init__(f"{device}: cannot hold {endpoint}: {cause}")


def _holder(pid: int | None) -> str:
    """`process PID (its command line, paths by their base names)`, `process PID` when /proc
    does not tell the command, `another process` without a PID."""
    if pid is None:
        return "another process"
    try:
        words = Path(f"/proc/{pid}/cmdline").read_bytes().rstrip(b"\0").split(b"\0")
    except OSError:
        return f"process {pid}"
    command = " ".join(_shown(" ".join(w.decode(errors="replace").split())) for w in words)
    if len(command) > COMMAND_SHOWN:
        command = command[:COMMAND_SHOWN - 3] + "..."
    return f"process {pid} ({command})" if command else f"process {pid}"


def _shown(word: str) -> str:
    """A command line word as the message shows it: a path by its base name
    (/usr/bin/python3.11: python3.11), any other word as it is."""
    if "/" not in word or " " in word or "://" in word:
        return word
    return Path(word).name or word


class HeldPort:
    """A port this process holds for `device` until `release()` (idempotent; also a context
    manager); `key` is the port as drivers.port_identity names it."""

    def __init__(self, fd: int | None = None, *, key: Path | str | None = None,
                 device: str = "", endpoint: str = "", lock_file: Path | None = None):
        self._fd, self._key, self._lock_file = fd, key, lock_file
        self.device, self.endpoint = device, endpoint
        self._serial = fd is not None and os.isatty(fd) \
            and not is_pty(os.fstat(fd))
        if key is not None:
            _held_here[key] = device

    def exclusive(self) -> None:
        """TIOCEXCL on a serial port once the transport has opened it (a property of the
        tty, set through the hold's own descriptor): later opens of the tty fail with EBUSY
        until release (root's do not: the flock is the guard for every process). Not on a
        pseudo-terminal; best effort: a port that refuses it is still held by the flock."""
        if self._serial:
            with contextlib.suppress(OSError):
                fcntl.ioctl(self._fd, termios.TIOCEXCL)

    def hand_over(self) -> None:
        """Before a transport's own exclusive open (pymodbus's serial client opens with
        pyserial's `exclusive=True`, its own flock), and again before each reopen: drop the
        hold's flock and the tty's exclusive flag, so that the open succeeds and its flock
        guards the port while it is open (the LCK file stays); `exclusive` then closes the
        tty to others again, and `take_back` takes the flock once the transport has closed.
        PortInUse if another process took the port in between."""
        if self._fd is None:
            return
        self._lock_device()
        self._shared()
        fcntl.flock(self._fd, fcntl.LOCK_UN)

    def take_back(self) -> None:
        """The hold's flock again, once the transport's own exclusive open has closed (a
        connection lost or closed): the port stays guarded until the next `hand_over`."""
        if self._fd is not None:
            with contextlib.suppress(PortInUse):  # taken meanwhile: hand_over will say by whom
                self._lock_device()

    def _lock_device(self) -> None:
        try:
            fcntl.flock(self._fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            path = self._key if isinstance(self._key, Path) else None
            raise PortInUse(self.device, self.endpoint, _flock_holder(path) if path else None,
                            device_file=path) from None

    def _shared(self) -> None:
        """Clear the tty's exclusive flag (TIOCNXCL; the hold's descriptor reaches the tty)."""
        if self._serial:
            with contextlib.suppress(OSError):
                fcntl.ioctl(self._fd, termios.TIOCNXCL)

    def release(self) -> None:
        """Give the port back: exclusive open cleared, flock dropped, our LCK file removed (a
        named lock file is emptied, kept: removing a locked file lets two processes lock)."""
        self._shared()
        fd, key, lock_file = self._fd, self._key, self._lock_file
        self._fd = self._key = self._lock_file = None
        if fd is not None:
            if isinstance(key, str):  # a named lock file: the PID goes while it is still ours
                with contextlib.suppress(OSError):
                    os.ftruncate(fd, 0)
            os.close(fd)
        if key is not None:
            _held_here.pop(key, None)
        if lock_file is not None:
            with contextlib.suppress(FileNotFoundError):
                if _lock_file_pid(lock_file) == os.getpid():
                    lock_file.unlink()

    def __enter__(self) -> HeldPort:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


def hold(endpoint: str, device: str) -> HeldPort:
    """Hold the port `endpoint` names for `device` (named in the error) before opening it:
    PortInUse if another process holds it, or this one for another device. A serial port
    this process cannot open is not held (the transport's own open then reports what is
    wrong with it); a VISA resource whose port cannot be held is Unholdable."""
    try:
        key, resource = port_identity(endpoint)
    except UnsettledPort as exc:
        raise Unholdable(device, endpoint, exc) from None
    path = key if isinstance(key, Path) else None
    if (other := _held_here.get(key)) is not None:
        raise PortInUse(device, endpoint, os.getpid(), device_file=path,
                        holder=f": already opened by this gonio for device {other}")
    if path is None:
        return _hold_by_name(key, endpoint, device)
    return _hold_device(path, resource, endpoint, device)


def _hold_device(path: Path, resource: bool, endpoint: str, device: str) -> HeldPort:
    """The device file's hold: a live holder's LCK file refuses before the device is opened;
    the flock, then (holding it) our LCK file in place of a dead process's."""
    lock_file = _uucp_lock_file(path)
    if lock_file is not None:
        _stale_lock_file(lock_file, device, endpoint, path)
    try:
        fd = os.open(path, DEVICE_OPEN)
    except OSError as exc:
        if exc.errno == errno.EBUSY:
            raise _exclusive_refusal(device, endpoint, path) from None
        if resource:
            raise Unholdable(device, endpoint, exc) from None
        return HeldPort()
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        lock_file = _write_lock_file(lock_file, device, endpoint, path)
    except BlockingIOError:
        os.close(fd)
        raise PortInUse(device, endpoint, _flock_holder(path), device_file=path) from None
    except BaseException:
        os.close(fd)
        raise
    return HeldPort(fd, key=path, device=device, endpoint=endpoint, lock_file=lock_file)


def _exclusive_refusal(device: str, endpoint: str, path: Path) -> PortInUse:
    """The refusal of an open that got EBUSY (the tty's exclusive flag): naming the flock's
    holder where there is one; else saying that the process that set it did not release it
    (no lock of any kind names it)."""
    pid = _flock_holder(path)
    if pid is not None:
        return PortInUse(device, endpoint, pid, " (opened for exclusive use)", path)
    return PortInUse(device, endpoint, None, device_file=path, holder=(
        ": opened for exclusive use by a process that did not release it (no lock names it); "
        f"end the program that has it open (fuser -v {path}) or unplug and replug the port"))


def uucp_lock_name(path: Path) -> str:
    """The device's UUCP lock file name: `LCK..` and its path below /dev, `/` as `_`
    (/dev/ttyUSB0: LCK..ttyUSB0; /dev/pts/3: LCK..pts_3)."""
    name = str(path)
    name = name.removeprefix("/dev/")
    return "LCK.." + name.replace("/", "_")


def _uucp_lock_file(path: Path) -> Path | None:
    """The device's LCK file in the first lock directory there is (None where there is none)."""
    folder = next((d for d in UUCP_LOCK_DIRS if d.is_dir()), None)
    return None if folder is None else folder / uucp_lock_name(path)


def _stale_lock_file(lock_file: Path, device: str, endpoint: str, path: Path) -> bool:
    """Whether the device's LCK file is there and a dead holder's (False: there is none);
    PortInUse for a live holder's, or one that names no PID we can read (its writer may be
    mid-write). It only reads the file."""
    try:
        pid = _lock_file_pid(lock_file)
    except FileNotFoundError:
        return False
    if pid is None:
        raise PortInUse(device, endpoint, None, f" (lock file {lock_file})", path)
    if _alive(pid):
        raise PortInUse(device, endpoint, pid, device_file=path)
    return True


def _write_lock_file(lock_file: Path | None, device: str, endpoint: str,
                     path: Path) -> Path | None:
    """Our LCK file, written while we hold the device's flock (a dead holder's removed first);
    None where the directory does not let us (then a live holder's file is only honoured);
    PortInUse for a live holder's file, written since the first look by a program that takes
    no flock."""
    if lock_file is None or not os.access(lock_file.parent, os.W_OK):
        return None
    while True:
        try:
            fd = os.open(lock_file, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        except FileExistsError:
            pass
        except OSError:  # refused after all (read-only, a security module): only honour
            return None
        else:
            with os.fdopen(fd, "w") as out:  # HDB UUCP: ten-byte ASCII PID, newline
                out.write(f"{os.getpid():10d}\n")
            return lock_file
        if not _stale_lock_file(lock_file, device, endpoint, path):
            continue  # removed since: try again
        try:
            lock_file.unlink()
        except FileNotFoundError:
            pass
        except OSError:  # a dead holder's file we may not remove: the flock still guards
            return None


def _lock_file_pid(lock_file: Path) -> int | None:
    """The PID a lock file holds (ASCII decimal, any spacing); None if it holds none or may
    not be read (FileNotFoundError passes: no file)."""
    try:
        pid = int(lock_file.read_bytes().strip() or b"0")
    except FileNotFoundError:
        raise
    except (OSError, ValueError):
        return None
    return pid if pid > 0 else None


def _alive(pid: int) -> bool:
    """Whether a process with this PID exists (another user's included)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _flock_holder(path: Path) -> int | None:
    """The PID holding a lock on the file at path, from /proc/locks (lines `N: FLOCK ADVISORY
    WRITE PID MAJ:MIN:INODE START END`, device numbers in hex); None if none is listed."""
    try:
        st = os.stat(path)
        table = Path("/proc/locks").read_text()
    except OSError:
        return None
    inode = f"{os.major(st.st_dev):02x}:{os.minor(st.st_dev):02x}:{st.st_ino}"
    for line in table.splitlines():
        fields = line.split()
        if len(fields) > 5 and fields[1] != "->" and fields[5] == inode \
                and fields[4].isdigit():
            return int(fields[4])
    return None


def lock_dir() -> Path:
    """Where the lock files of resources that name no device file live, the same for every
    gonio process on the machine: $GONIO_LOCK_DIR if set, else `gonio` in /run/lock (or
    /var/lock) where that is writable by all, else /tmp/gonio-locks; made writable by all."""
    if configured := os.environ.get(LOCK_DIR_ENV):
        return Path(configured)
    shared = (d for d in UUCP_LOCK_DIRS if d.is_dir() and d.stat().st_mode & stat.S_IWOTH)
    folder = next((d / "gonio" for d in shared), FALLBACK_LOCK_DIR)
    try:
        folder.mkdir()
    except FileExistsError:
        return folder
    folder.chmod(SHARED_DIR_MODE)
    return folder


def _hold_by_name(name: str, endpoint: str, device: str) -> HeldPort:
    """An flock'd lock file for a resource that names no device file (`name` its canonical
    name), our PID in it."""
    lock_path = Path(quote(name, safe="") + ".lock")
    try:
        lock_path = lock_dir() / lock_path
        fd = _open_shared(lock_path)
    except OSError as exc:
        raise _cannot_hold(device, endpoint, exc, lock_path) from None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        pid = _lock_file_pid(lock_path)
        os.close(fd)
        raise PortInUse(device, endpoint, pid) from None
    try:
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
    except BaseException as exc:  # not held: the lock goes with the descriptor
        os.close(fd)
        if isinstance(exc, OSError):  # a full disk, a file-size limit
            raise _cannot_hold(device, endpoint, exc, lock_path) from None
        raise
    return HeldPort(fd, key=name, device=device, endpoint=endpoint)


def _cannot_hold(device: str, endpoint: str, exc: OSError, lock_path: Path) -> DriverError:
    """The error of a lock file that could not be opened or written: why, and which file."""
    return DriverError(f"{device}: cannot hold {endpoint}: {exc.strerror or exc}: "
                       f"{exc.filename or lock_path}")


def _open_shared(lock_path: Path) -> int:
    """A descriptor of a lock file any user may lock, made (mode 0666) if missing. An
    existing file is opened without O_CREAT: a sticky shared directory refuses O_CREAT on
    another user's file (fs.protected_regular)."""
    while True:
        try:
            return os.open(lock_path, os.O_RDWR)
        except FileNotFoundError:
            pass
        try:
            fd = os.open(lock_path, os.O_RDWR | os.O_CREAT | os.O_EXCL, 0o666)
        except FileExistsError:
            continue  # made by another process since: open it
        os.fchmod(fd, 0o666)  # whatever the umask
        return fd
