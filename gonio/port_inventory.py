"""What `gonio devices --list` shows: this machine's serial ports (pyserial) and VISA
resources (PyVISA's pyvisa-py backend), each as the config line that reaches it
(`port = "..."`, `resource = "..."`) with what identifies the device behind it.

Only serial and USB resources are asked for: pyvisa-py's own `list_resources` also runs its
TCPIP discovery (a VXI-11 broadcast on every network, then a one-second wait) whatever the
query, so its serial and USB session classes are asked directly instead.
"""

from __future__ import annotations

import os
from pathlib import Path

BY_ID = Path("/dev/serial/by-id")
SYSFS_USB = Path("/sys/bus/usb/devices")
#: The VISA interfaces listed (pyvisa.constants.InterfaceType names), resource class INSTR.
VISA_INTERFACES = ("asrl", "usb")
INSTALL_HINT = "pip install gonio[visa]"
#: What the distributions of the modules PyVISA listing needs are called.
DISTRIBUTIONS = {"pyvisa": "pyvisa", "pyvisa_py": "pyvisa-py"}


def stable_names(folder: Path = BY_ID) -> dict[str, str]:
    """{device path: its link in `folder`} for udev's persistent names (/dev/serial/by-id),
    which survive a replug into another socket; {} where there are none."""
    try:
        links = sorted(folder.iterdir())
    except OSError:
        return {}
    return {os.path.realpath(link): str(link) for link in links}


def _comment(details: list[str | None]) -> str:
    shown = [d for d in details if d]
    return f"  # {', '.join(shown)}" if shown else ""


def _usb_id(vendor: int | None, product: int | None) -> str | None:
    """`vvvv:pppp` in hex, as lsusb prints it (None when either is unknown)."""
    return None if vendor is None or product is None else f"{vendor:04x}:{product:04x}"


def serial_port_lines(by_id: Path = BY_ID) -> list[str]:
    """One `port = "..."` line per serial port pyserial finds (its by-id name where udev gives
    one), with its device, USB vendor:product id, manufacturer, product and serial number."""
    from serial.tools import list_ports

    names = stable_names(by_id)
    lines = []
    for port in sorted(list_ports.comports(), key=lambda p: p.device):
        stable = names.get(os.path.realpath(port.device))
        serial = f"serial {port.serial_number}" if port.serial_number else None
        details = [port.device if stable else None, _usb_id(port.vid, port.pid),
                   port.manufacturer, port.product, serial]
        lines.append(f'port = "{stable or port.device}"{_comment(details)}')
    return lines


def usb_strings(vendor: int, product: int, serial: str,
                root: Path = SYSFS_USB) -> tuple[str | None, str | None]:
    """(manufacturer, product) of the USB device with these ids and serial number, as the
    kernel read them when it was plugged in (Linux sysfs; (None, None) elsewhere)."""
    def text(folder: Path, name: str) -> str | None:
        try:
            return (folder / name).read_text().strip()
        except OSError:
            return None

    try:
        folders = sorted(root.iterdir())
    except OSError:
        return None, None
    for folder in folders:
        try:
            ids = int(text(folder, "idVendor") or "", 16), int(text(folder, "idProduct") or "", 16)
        except ValueError:  # a hub's interface folder, or no ids
            continue
        if ids == (vendor, product) and text(folder, "serial") == serial:
            return text(folder, "manufacturer"), text(folder, "product")
    return None, None


def _resource_line(name: str) -> str:
    """`resource = "..."`; a USB resource with its vendor:product id, names and serial."""
    from pyvisa import rname

    parsed = rname.parse_resource_name(name)
    if not isinstance(parsed, rname.USBInstr):
        return f'resource = "{name}"'
    vendor, product = int(parsed.manufacturer_id, 0), int(parsed.model_code, 0)
    details = [_usb_id(vendor, product), *usb_strings(vendor, product, parsed.serial_number),
               f"serial {parsed.serial_number}"]
    return f'resource = "{name}"{_comment(details)}'


def visa_lines() -> list[str]:
    """The VISA section: a heading, then one `resource = "..."` line per serial and USB-TMC
    resource pyvisa-py finds, or a line saying why an interface cannot be listed; one line
    alone when PyVISA is not installed."""
    try:
        import pyvisa
        from pyvisa_py.sessions import Session
    except ImportError as exc:
        missing = DISTRIBUTIONS.get(exc.name or "", exc.name)
        return [f"VISA: {missing} not installed ({INSTALL_HINT})"]
    manager = pyvisa.ResourceManager("@py")  # loads the backend's session classes
    try:
        lines = []
        for (interface, kind), issue in Session.iter_session_classes_issues():
            if interface.name in VISA_INTERFACES and kind == "INSTR":
                lines.append(f"VISA {interface.name.upper()}: unavailable: "
                             f"{str(issue).splitlines()[0]}")
        for (interface, kind), session in Session.iter_valid_session_classes():
            if interface.name in VISA_INTERFACES and kind == "INSTR":
                try:
                    lines += [_resource_line(name) for name in session.list_resources()]
                except (OSError, ValueError, NotImplementedError) as exc:  # no USB backend
                    lines.append(f"VISA {interface.name.upper()}: cannot list: {exc}")
    finally:
        manager.close()
    return _section("VISA resources (pyvisa-py: ASRL and USB INSTR):", lines)


def _section(heading: str, lines: list[str]) -> list[str]:
    return [heading, *(f"  {line}" for line in lines or ["none found"])]


def inventory_lines() -> list[str]:
    """Everything `gonio devices --list` prints: serial ports, then VISA resources."""
    return [*_section("serial ports (pyserial):", serial_port_lines()), *visa_lines()]
