"""The one place a device's byte link is opened: a serial port (drivers.serial_link) or a VISA
resource (drivers.visa_link), whichever the device is given, held for the device
(drivers.port_lock) from before it opens."""

from __future__ import annotations

from drivers.byte_link import ByteLink, LineSettings, LinkFailure, on_the_line
from drivers.open_failure import port_open_failure
from drivers.port_identity import device_path
from drivers.port_lock import HeldPort, Unholdable, hold
from drivers.serial_link import SerialLink
from drivers.visa_link import VisaLink


def open_byte_link(port: str | None, resource: str | None, line: LineSettings,
                   read_eol: bytes, timeout_s: float,
                   device: str) -> tuple[ByteLink, HeldPort]:
    """Open the link to a device given by exactly one of a serial port or a VISA resource
    string (ValueError otherwise; LinkFailure if it cannot be opened, or is a resource whose
    port cannot be held); line settings apply to
    a port and to an ASRL resource (no parity on a pseudo-terminal). read_eol ends each reply
    (a VISA read returns one line); timeout_s bounds a write. The hold (PortInUse, naming
    `device`, if another process has it) is taken before the link opens and given back with
    it: release it after closing the link. A serial port, an ASRL resource's included, is also
    opened for exclusive use (TIOCEXCL) once the link is open."""
    if (port is None) == (resource is None):
        raise ValueError("give a serial port or a VISA resource, exactly one of them; got "
                         f"port {port!r} and resource {resource!r}")
    endpoint = port if resource is None else resource
    line = on_the_line(line, device_path(endpoint))
    try:
        held = hold(endpoint, device)
    except Unholdable as exc:  # a resource that cannot be held is not opened either
        raise LinkFailure(port_open_failure(exc.cause)) from exc
    try:
        link: ByteLink = SerialLink(port, line, timeout_s) if resource is None \
            else VisaLink(resource, line, read_eol, timeout_s)
        held.exclusive()
        return link, held
    except BaseException:
        held.release()
        raise
