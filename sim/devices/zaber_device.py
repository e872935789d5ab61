"""One emulated Zaber device on the daisy chain: its address, axes, the device-scope settings of
firmware 7 that a client reads while it detects and identifies devices, and its messages
(replies and alerts, checksummed while comm.checksum is 1).

Which settings a detect / identify reads comes from the clients themselves (zaber-motion 10
sends, in order: `get comm.packet.size.max`, `deviceid`, `system.serial`, `version`,
`version.build`, `device.hw.modified`, `comm.command.packets.max`, `comm.word.size.max`,
`get.settings.max`, `system.axiscount`, then per axis `resolution` and `peripheralid`). An
integrated product such as the X-RSW60A has no peripheral: its axes reject `peripheralid`
and `peripheral.serial` with BADCOMMAND, as Zaber's MATLAB toolbox tests show for an
integrated rotary stage.
"""

from __future__ import annotations

import re
from collections.abc import Callable

from sim.devices.zaber_axis import EmulatedAxis, Reject

#: what `get deviceid` answers by default: the id Zaber's MATLAB toolbox tests give an
#: integrated rotary stage (the X-RSW60A's own id is in Zaber's device database, out of reach
#: here; `device_id` sets the one a bench's product reports)
DEVICE_ID = 50001
FIRMWARE = "7.38"  # `get version`
FIRMWARE_BUILD = 12870  # `get version.build`: the emulator's own number
SERIAL_BASE = 120000  # device n answers system.serial SERIAL_BASE + n
BAUD = 115200  # comm.rs232.baud: the X-series default

#: limits the emulator declares to clients: one setting a `get`, one packet a command (no `\`
#: continuation), a packet and a word of up to 80 characters
LIMITS = {"comm.packet.size.max": 80, "comm.command.packets.max": 1,
          "comm.word.size.max": 80, "get.settings.max": 1}

#: device settings `set` may change, with the values each takes
WRITABLE = {"comm.alert": (0, 1), "comm.checksum": (0, 1)}

_FIRMWARE_7 = re.compile(r"7\.\d+")


def _must_be(accepts: Callable[[object], bool], expected: str) -> Callable[[object], str | None]:
    """A check of one value: None if `accepts` it, else what it must be and what it is."""
    def problem(value: object) -> str | None:
        return None if accepts(value) else f"must be {expected}, got {value!r}"
    return problem


#: what the emulated product says it is, checked alike as ZaberEmulator's arguments and as a
#: config's [sim.devices.<name>] keys: each key's check (None, or what is wrong)
IDENTITY_CHECKS: dict[str, Callable[[object], str | None]] = {
    "device_id": _must_be(lambda v: isinstance(v, int) and not isinstance(v, bool) and v >= 1,
                          "a positive integer (the product's Zaber device id)"),
    "firmware": _must_be(lambda v: isinstance(v, str) and _FIRMWARE_7.fullmatch(v) is not None,
                         'a firmware-7 version such as "7.38" (the protocol emulated)'),
    "alerts": _must_be(lambda v: isinstance(v, bool),
                       "true or false (the comm.alert the device saved)"),
}


def lrc(text: str) -> str:
    """The manual's message checksum of `text`, two upper-case hex digits."""
    return f"{-sum(text.encode('ascii')) & 0xFF:02X}"


def by_priority(flags: list[str]) -> list[str]:
    """Warning flags, faults (F) first, then warnings (W), then notices (N)."""
    return sorted(flags, key=lambda flag: "FWN".index(flag[0]))


class EmulatedDevice:
    """One device on the chain: its address, axes and device-scope settings."""

    def __init__(self, address: int, axes: dict[int, EmulatedAxis], device_id: int,
                 firmware: str, alerts: bool):
        self.address, self.axes = address, axes
        self.settings: dict[str, int | str] = {
            "deviceid": device_id, "version": firmware, "version.build": FIRMWARE_BUILD,
            "system.serial": SERIAL_BASE + address, "system.axiscount": len(axes),
            "device.hw.modified": 0, "comm.address": address, "comm.rs232.baud": BAUD,
            **LIMITS, "comm.alert": int(alerts), "comm.checksum": 0}

    def status(self, axis: int) -> tuple[str, str]:
        """BUSY/IDLE and the warning flag of an axis, or of the device (axis 0): busy if any
        axis is, and the highest-priority flag of any axis."""
        chosen = [self.axes[axis]] if axis else list(self.axes.values())
        flags = by_priority([w for a in chosen if (w := a.warning()) != "--"])
        return ("BUSY" if any(a.busy() for a in chosen) else "IDLE"), (flags + ["--"])[0]

    @property
    def alerting(self) -> bool:
        """comm.alert is on: motions that end send an alert."""
        return bool(self.settings["comm.alert"])

    def alerts(self) -> list[str]:
        """Alerts of the axes whose motion has ended since it started (comm.alert 1)."""
        found = []
        for number, axis in self.axes.items():
            if axis.alert_pending and not axis.busy():
                axis.alert_pending = False
                found.append(self.message("!", f"{number} IDLE {axis.warning()}"))
        return found

    def message(self, kind: str, body: str) -> str:
        """A message of this device: kind, address, body, and the checksum if it is on."""
        text = f"{self.address:02d} {body}"
        return kind + (f"{text}:{lrc(text)}" if self.settings["comm.checksum"] else text)

    def get(self, name: str) -> str:
        """A device setting's value."""
        return str(self.settings[name])

    def set(self, name: str, value: int) -> None:
        """Write a device setting: BADCOMMAND for a read-only one, BADDATA for a value it
        does not take."""
        if name not in WRITABLE:
            raise Reject("BADCOMMAND")
        if value not in WRITABLE[name]:
            raise Reject("BADDATA")
        self.settings[name] = value
