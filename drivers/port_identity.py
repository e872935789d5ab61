"""What a port or VISA resource string names, so that one device written two ways is one port
to hold (drivers.port_lock): the device file it opens, or a resource's canonical name.

A string PyVISA parses as a resource (`rname.parse_resource_name`; VISA names are
case-insensitive, `::INSTR` may be left out) is a resource: an ASRL resource names its board's
device file (`ASRL/dev/ttyUSB0`, `ASRL/dev/serial/by-path/pci-0000:00:14.0-usb-0:2:1.0-port0::
INSTR`), any other is named canonically (USB ids as numbers, the serial number in upper case,
a host by its address). A URL (`socket://host:port`, gonio's `modbus-tcp://host:port` for a
Modbus TCP server) names its host by its address too. Anything else is a port: a device file.
Only a string that may be a resource is given to PyVISA (imported then), so a serial port's
name costs no import.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import os
import socket
from pathlib import Path
from typing import Any, NamedTuple
from urllib.parse import urlsplit

from drivers.visa_link import visa_name

USB_IDS = ("manufacturer_id", "model_code")  # a USB resource's ids: hex or decimal alike
HOST = "host_address"
#: how every VISA resource name begins (its interface type): only such a string, or one with
#: `::` in it, may be a resource
VISA_INTERFACES = ("ASRL", "USB", "TCPIP", "GPIB", "VXI", "PXI", "VICP", "FIREWIRE")


class PortIdentity(NamedTuple):
    """The device file an endpoint opens (symlinks resolved) or, for a resource that names no
    file, its canonical name; `resource`: given as a VISA resource string."""

    key: Path | str
    resource: bool


class UnsettledPort(ValueError):
    """A resource that names a serial port gonio cannot find the device file of."""


def port_identity(endpoint: str) -> PortIdentity:
    """What endpoint names; UnsettledPort for an ASRL resource whose board is not a device
    path (`ASRL1::INSTR`: the VISA library's own numbering of ports)."""
    text = endpoint.strip()
    if "://" in text:
        return PortIdentity(_url_key(text), False)
    resource = _visa_resource(text) if may_be_resource(text) else None
    if resource is None:
        if "::" in text:  # no PyVISA, or no resource it knows: only the case to fold
            return PortIdentity(text.upper(), True)
        return PortIdentity(Path(os.path.realpath(endpoint)), False)
    if resource.interface_type == "ASRL":
        if not resource.board.startswith("/"):
            raise UnsettledPort(f"ASRL{resource.board} names no device file: write the port's "
                                "path, as in ASRL/dev/ttyUSB0::INSTR")
        return PortIdentity(Path(os.path.realpath(resource.board)), True)
    return PortIdentity(_canonical(resource), True)


def may_be_resource(text: str) -> bool:
    """True for a string that may be a VISA resource name (it has `::` or begins with an
    interface type); a device path never is."""
    return "::" in text or text.upper().startswith(VISA_INTERFACES)


def tcp_url(scheme: str, host: str, port: int) -> str:
    """`scheme://host:port`, an IPv6 address in brackets: how a TCP endpoint is named."""
    return f"{scheme}://[{host}]:{port}" if ":" in host else f"{scheme}://{host}:{port}"


def port_key(endpoint: str) -> str:
    """What a port or resource is known by wherever gonio asks whether two are one (the hold,
    a Modbus bus's shared link, a daisy chain, a config's devices): port_identity's key as
    text; an ASRL resource that names no device file as written (its opening says why)."""
    try:
        return str(port_identity(endpoint).key)
    except UnsettledPort:
        return endpoint


def device_path(endpoint: str) -> Path | None:
    """The device file an endpoint opens, symlinks resolved; None for one that names none
    (a VISA resource other than ASRL, a pyserial URL)."""
    with contextlib.suppress(UnsettledPort):
        key = port_identity(endpoint).key
        return key if isinstance(key, Path) else None
    return None


def _visa_resource(endpoint: str) -> Any | None:
    """PyVISA's parse of endpoint (its resource class in upper case if that alone stops the
    parse); None without PyVISA or for a string that is no resource."""
    try:
        from pyvisa import rname
    except ImportError:
        return None
    with contextlib.suppress(rname.InvalidResourceName):
        return rname.parse_resource_name(visa_name(endpoint))
    return None


def _canonical(resource: Any) -> str:
    """A resource in PyVISA's canonical form (board and defaults written out), upper case,
    with USB ids in hex as VISA writes them (0x1313) and a host name as its address."""
    fields = {f.name: value.upper() for f in dataclasses.fields(resource)
              if isinstance(value := getattr(resource, f.name), str)}
    fields |= {name: f"0x{number:04X}" for name in USB_IDS
               if (number := _number(getattr(resource, name, None))) is not None}
    if (host := getattr(resource, HOST, None)) is not None:
        fields[HOST] = _address(host).upper()
    return str(dataclasses.replace(resource, **fields))


def _number(text: str | None) -> int | None:
    """A USB id as written (0x1313 or 4883) as a number; None if it is none."""
    with contextlib.suppress(TypeError, ValueError):
        return int(text, 0)
    return None


def _url_key(url: str) -> str:
    """A URL with its host as the address it resolves to (upper case: IPv6 hex), else as
    written (no host and port in it)."""
    parts = urlsplit(url)
    try:
        host, port = parts.hostname, parts.port
    except ValueError:  # a port that is no number: the link's opening says so
        return url
    if host is None or port is None:
        return url
    return tcp_url(parts.scheme, _address(host).upper(), port)


@functools.lru_cache(maxsize=64)
def _address(host: str) -> str:
    """The address a host name resolves to (IPv4 first, as a client connects); the name as
    written where it does not resolve (the link's connect then says so). Asked once per host
    in a process: a config's checks and a run's holds name the same hosts again and again."""
    try:
        found = socket.getaddrinfo(host, None, type=socket.SOCK_STREAM)
    except (OSError, UnicodeError):
        return host
    found.sort(key=lambda info: info[0] != socket.AF_INET)
    return str(found[0][4][0]) if found else host
