"""The one place a device's byte link is opened: a serial port (drivers.serial_link) or a VISA
resource (drivers.visa_link), whichever the device is given."""

from __future__ import annotations

from drivers.byte_link import ByteLink, LineSettings
from drivers.serial_link import SerialLink
from drivers.visa_link import VisaLink


def open_byte_link(port: str | None, resource: str | None, line: LineSettings,
                   read_eol: bytes, timeout_s: float) -> ByteLink:
    """Open the link to a device given by exactly one of a serial port or a VISA resource
    string (ValueError otherwise; LinkFailure if it cannot be opened); line settings apply to
    a port and to an ASRL resource. read_eol ends each reply (a VISA read returns one line);
    timeout_s bounds a write."""
    if (port is None) == (resource is None):
        raise ValueError("give a serial port or a VISA resource, exactly one of them; got "
                         f"port {port!r} and resource {resource!r}")
    if resource is not None:
        return VisaLink(resource, line, read_eol, timeout_s)
    return SerialLink(port, line, timeout_s)
