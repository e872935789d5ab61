"""Ports held for a run: one process at a time on a serial port or an instrument resource.

`hold(endpoint, device)` is taken before a transport opens its port, so that a port another
process holds is refused (`PortInUse`, naming the port and the holder) before the refused
process touches the line: no termios change, no DTR toggle, no byte. What holds it:

- a device file (symlinks such as /dev/serial/by-id/... resolved; a VISA `ASRL<path>::INSTR`
  resource names one too), by the platform's conventions on Linux: the UUCP / FHS lock file
  `LCK..<name>` in /run/lock (or /var/lock), a live holder's honoured, a dead one's removed,
  ours written (where the directory lets us) and removed on release; and
  `flock(LOCK_EX | LOCK_NB)` on a descriptor of the device (the lock pyserial's
  `exclusive=True`, picocom and others take; its holder's PID from /proc/locks). Once the
  transport has opened the port, `HeldPort.exclusive(fd)` sets TIOCEXCL (further opens of the
  tty fail with EBUSY, root's excepted), cleared on release.
- anything else (a VISA resource such as `TCPIP0::host::5025::SOCKET`, a pyserial URL): an
  flock'd file named from the normalised endpoint in the gonio lock directory (`lock_dir`),
  our PID written in it.

The flocks end with the process however it ends; a LCK file a killed process left names a
dead PID, and the next holder removes it.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import re
import stat
import termios
from pathlib import Path
from urllib.parse import quote

from drivers.base import DriverError

UUCP_LOCK_DIRS = (Path("/run/lock"), Path("/var/lock"))  # FHS, then its older name
LOCK_DIR_ENV = "GONIO_LOCK_DIR"
FALLBACK_LOCK_DIR = Path("/tmp/gonio-locks")
SHARED_DIR_MODE = 0o1777  # every user's gonio writes there; none removes another's file
COMMAND_SHOWN = 80  # characters of the holder's command line in the message
# how the device is opened to be locked: no controlling tty, no wait for carrier
DEVICE_OPEN = os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK
VISA_ASRL_PATH = re.compile(r"ASRL(/[^:]+)::INSTR", re.IGNORECASE)


class PortInUse(DriverError):
    """Another process holds the port (as configured; `device_file` what it resolves to):
    `holder_pid` names it (None where the platform does not tell); the message is one line
    naming the port and the holder, `how` saying more of the lock that refused."""

    def __init__(self, device: str, port: str, holder_pid: int | None, how: str = "",
                 device_file: Path | None = None):
        self.device, self.port, self.holder_pid = device, port, holder_pid
        resolved = f" ({device_file})" if device_file and str(device_file) != port else ""
        super().__init__(f"{device}: {port}{resolved} is in use by {_holder(holder_pid)}{how}")


def _holder(pid: int | None) -> str:
    """`process PID (its command line)`, `process PID` when /proc does not tell the command,
    `another process` without a PID."""
    if pid is None:
        return "another process"
    try:
        words = Path(f"/proc/{pid}/cmdline").read_bytes().rstrip(b"\0").split(b"\0")
    except OSError:
        return f"process {pid}"
    command = " ".join(" ".join(w.decode(errors="replace").split()) for w in words)
    if len(command) > COMMAND_SHOWN:
        command = command[:COMMAND_SHOWN - 3] + "..."
    return f"process {pid} ({command})" if command else f"process {pid}"


class HeldPort:
    """A port this process holds until `release()` (idempotent; also a context manager)."""

    def __init__(self, fd: int | None = None, *, tty: bool = False,
                 lock_file: Path | None = None, named: bool = False):
        self._fd, self._tty, self._lock_file, self._named = fd, tty, lock_file, named

    def exclusive(self, fd: int) -> None:
        """TIOCEXCL on the port the transport opened on `fd`: later opens of the tty fail with
        EBUSY until release (root's do not: the flock is the guard for every process). Best
        effort: a port that refuses it is still held by the flock."""
        if self._tty:
            with contextlib.suppress(OSError):
                fcntl.ioctl(fd, termios.TIOCEXCL)

    def hand_over(self) -> None:
        """Before a transport's own exclusive open (pymodbus's serial client opens with
        pyserial's `exclusive=True`, its own flock), and again before each reopen: drop the
        hold's flock and the tty's exclusive flag (a pty's outlives every descriptor of it),
        so that the open succeeds and its flock guards the port while it is open; the LCK
        file stays. `exclusive` then closes the tty to others again."""
        self._shared()
        if self._fd is not None:
            fcntl.flock(self._fd, fcntl.LOCK_UN)

    def _shared(self) -> None:
        """Clear the tty's exclusive flag (TIOCNXCL; the hold's descriptor reaches the tty)."""
        if self._tty and self._fd is not None:
            with contextlib.suppress(OSError):
                fcntl.ioctl(self._fd, termios.TIOCNXCL)

    def release(self) -> None:
        """Give the port back: exclusive open cleared, flock dropped, our LCK file removed (a
        named lock file is emptied, kept: removing a locked file lets two processes lock)."""
        self._shared()
        fd, lock_file = self._fd, self._lock_file
        self._fd = self._lock_file = None
        if fd is not None:
            if self._named:  # the PID goes while the lock is still ours
                with contextlib.suppress(OSError):
                    os.ftruncate(fd, 0)
            os.close(fd)
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
    PortInUse if another process holds it. A device file this process cannot open is not
    held: the transport's own open then reports what is wrong with it."""
    path = device_path(endpoint)
    if path is None:
        return _hold_by_name(endpoint, device)
    lock_file = _claim_uucp_lock(path, device, endpoint)
    try:
        fd = os.open(path, DEVICE_OPEN)
    except OSError as exc:
        _remove(lock_file)
        if exc.errno == errno.EBUSY:
            raise PortInUse(device, endpoint, _flock_holder(path),
                            " (opened for exclusive use)", path) from None
        return HeldPort()
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        _remove(lock_file)
        raise PortInUse(device, endpoint, _flock_holder(path), device_file=path) from None
    return HeldPort(fd, tty=os.isatty(fd), lock_file=lock_file)


def device_path(endpoint: str) -> Path | None:
    """The device file an endpoint opens, symlinks resolved; None for one that names no file
    (a VISA resource other than `ASRL<path>::INSTR`, a pyserial URL such as socket://)."""
    if "::" in endpoint:
        asrl = VISA_ASRL_PATH.fullmatch(endpoint.strip())
        if asrl is None:
            return None
        endpoint = asrl.group(1)
    elif "://" in endpoint:
        return None
    return Path(os.path.realpath(endpoint))


def uucp_lock_name(path: Path) -> str:
    """The device's UUCP lock file name: `LCK..` and its path below /dev, `/` as `_`
    (/dev/ttyUSB0: LCK..ttyUSB0; /dev/pts/3: LCK..pts_3)."""
    name = str(path)
    name = name.removeprefix("/dev/")
    return "LCK.." + name.replace("/", "_")


def _claim_uucp_lock(path: Path, device: str, endpoint: str) -> Path | None:
    """Our LCK file for the device in the first lock directory there is (None where there is
    none, or it is not writable and holds no live holder's file); PortInUse for a live
    holder's file, or one that names no PID we can read (its writer may be mid-write)."""
    folder = next((d for d in UUCP_LOCK_DIRS if d.is_dir()), None)
    if folder is None:
        return None
    lock_file = folder / uucp_lock_name(path)
    writable = os.access(folder, os.W_OK)
    while True:
        if writable:
            try:
                fd = os.open(lock_file, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
            except FileExistsError:
                pass
            except OSError:  # refused after all (read-only, a security module): only honour
                writable = False
            else:
                with os.fdopen(fd, "w") as out:  # HDB UUCP: ten-byte ASCII PID, newline
                    out.write(f"{os.getpid():10d}\n")
                return lock_file
        try:
            pid = _lock_file_pid(lock_file)
        except FileNotFoundError:
            if writable:
                continue  # removed since: try again
            return None
        if pid is None:
            raise PortInUse(device, endpoint, None, f" (lock file {lock_file})", path)
        if _alive(pid):
            raise PortInUse(device, endpoint, pid, device_file=path)
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


def _remove(lock_file: Path | None) -> None:
    """Remove our LCK file after a refusal (no file: nothing to do)."""
    if lock_file is not None:
        with contextlib.suppress(FileNotFoundError):
            lock_file.unlink()


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


def normalised(endpoint: str) -> str:
    """The endpoint as its lock file is named: a VISA resource in its canonical form
    (PyVISA's: board 0 and the defaults written out) and upper case (VISA resource names are
    case-insensitive); anything else as written, spaces stripped."""
    text = endpoint.strip()
    if "::" not in text:
        return text
    try:
        from pyvisa import rname
    except ImportError:  # no PyVISA: no VISA transport either, only the case to fold
        return text.upper()
    with contextlib.suppress(rname.InvalidResourceName):
        text = str(rname.parse_resource_name(text))
    return text.upper()


def _hold_by_name(endpoint: str, device: str) -> HeldPort:
    """An flock'd lock file for a resource that names no device file, our PID in it."""
    lock_path = Path(quote(normalised(endpoint), safe="") + ".lock")
    try:
        lock_path = lock_dir() / lock_path
        fd = _open_shared(lock_path)
    except OSError as exc:
        raise DriverError(f"{device}: cannot hold {endpoint}: {exc.strerror or exc}: "
                          f"{exc.filename or lock_path}") from None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        pid = _lock_file_pid(lock_path)
        os.close(fd)
        raise PortInUse(device, endpoint, pid) from None
    os.ftruncate(fd, 0)
    os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
    return HeldPort(fd, named=True)


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
