"""Where a device on a line of its own is reached, read from its config rather than found out
when it opens: a serial port is no VISA resource string, a VISA resource is one PyVISA parses,
of a class that exchanges lines (gonio.device_kinds.line_checks checks devices against each
other and against the VISA backend).
"""

from __future__ import annotations

from typing import Any

from drivers.port_identity import may_be_resource
from drivers.visa_link import line_resource

#: The setting types whose value is a device file or a VISA resource a device is reached by.
LINK_TYPES = ("port", "resource")


def serial_port(port: str, alternative: bool) -> str:
    """A serial port (a device file, or a pyserial URL); a VISA resource string is refused
    (ValueError), pointing at the `resource` setting when the device may be given one
    (`alternative`)."""
    if "://" in port or not may_be_resource(port.strip()):
        return port
    hint = (f'; give it as resource = "{port}"' if alternative else
            "; give the line's device file, such as /dev/ttyUSB0")
    raise ValueError(f"{port!r} is a VISA resource string, not a serial port{hint}")


def visa_resource(resource: str) -> str:
    """A VISA resource string PyVISA parses, of a class that exchanges lines (INSTR,
    SOCKET); ValueError saying what is wrong, or that PyVISA is missing."""
    try:
        line_resource(resource)
    except ImportError as exc:
        raise ValueError(f"{exc}: a VISA resource is opened through it") from None
    except ValueError as exc:
        raise ValueError(f"{resource!r} is not a VISA resource a line device is reached by: "
                         f"{exc}") from None
    return resource


def socket_resource(resource: str) -> bool:
    """Whether a (valid) resource is a raw TCP one, `TCPIP::host::port::SOCKET`."""
    return line_resource(resource).resource_class == "SOCKET"


def read_link(value: Any, setting_type: str, alternative: bool) -> Any:
    """A port's or resource's value read from a config (None: not given), or ValueError."""
    if value is None:
        return None
    return serial_port(value, alternative) if setting_type == "port" else visa_resource(value)
