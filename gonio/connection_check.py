"""The check behind `gonio devices CONFIG`: open every device of a config as a scan does
(gonio.instrument) and report who each says it is, where each axis stands, what the
detector and the environment sensor read, without moving anything or pushing any of the
config's settings; and whether the detector can measure at the config's wavelength, where it
tells its sensor head's range.

No Axis.configure (speed, acceleration, travel limits), no Detector.configure (wavelength,
averaging, range), no home and no move is sent. What a driver does to open a device still
happens, since its replies rest on it: an ESP axis is switched on in degrees (MO, SN7), a
Zaber device's replies carry checksums (its alerts are left on or off as saved), a PM100
measures power (CONF:POW). Each device is opened on its own, so one that cannot be reached
(its port missing or held, no reply) is one line of the report and the others are still
asked. A head whose range leaves out the config's wavelength (1550 nm on a silicon head) is a
line of its own, a problem of its device as one that does not answer is.
"""

from __future__ import annotations

import termios
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from drivers.base import DriverError, HeadRange, InvalidReading, WavelengthOutsideHead
from gonio.config import InstrumentConfig
from gonio.device_kinds import DeviceConfig
from gonio.device_kinds.kind import AxisConfig
from gonio.errors import GonioError
from gonio.instrument import axis_of, close_all, open_device

#: What a device that cannot be reached or does not answer raises: a missing or held port
#: (ConfigError, DriverError), no reply or a garbled one, a device error, a line that fails.
UNANSWERED = (DriverError, GonioError, OSError, ValueError, termios.error)


@dataclass(frozen=True)
class Answer:
    """One line of the report: its subject (`device esp (...)`, `axis arm (esp.2)`,
    `detector (pm100)`), the device asked, and what it said or why it did not answer;
    problem: what it said means it cannot be used as configured."""

    subject: str
    device: str
    text: str
    answered: bool
    problem: bool = False

    def __str__(self) -> str:
        return f"{self.subject}: {self.text}" if self.answered else \
            f"{self.subject}: did not answer: {self.text}"


@dataclass(frozen=True)
class ConnectionReport:
    """Every line of a check, devices first (config order), then axes, then the detector."""

    answers: list[Answer]

    @property
    def silent(self) -> list[str]:
        """The devices that did not answer something asked of them, in config order."""
        return list(dict.fromkeys(a.device for a in self.answers if not a.answered))

    @property
    def unfit(self) -> list[str]:
        """The devices that answered something that keeps them from running as configured."""
        return list(dict.fromkeys(a.device for a in self.answers if a.problem))

    def lines(self) -> list[str]:
        """The report as printed, one line per answer."""
        return [str(a) for a in self.answers]


def _asked(subject: str, device: str, ask: Callable[[], str]) -> Answer:
    """The answer `ask()` gives, or why the device gave none."""
    try:
        return Answer(subject, device, ask(), True)
    except UNANSWERED as exc:
        return Answer(subject, device, str(exc) or type(exc).__name__, False)


def identity_text(identity: dict[str, str]) -> str:
    """A device's identity as one line, `key: value; ...` in the order it reported them."""
    if not identity:
        return "reported no identity"
    return "; ".join(f"{key}: {value}" for key, value in identity.items())


def device_subject(dev: DeviceConfig) -> str:
    """`device NAME (PROTOCOL at ENDPOINT, ...)`, with the settings a run records (a Modbus
    device's transport and unit id)."""
    recorded = "".join(f", {key} {value}" for key, value in dev.recorded.items())
    return f"device {dev.name} ({dev.protocol} at {dev.endpoint}{recorded})"


def axis_subject(dev: DeviceConfig, ax: AxisConfig) -> str:
    """`axis ROLE (DEVICE.AXIS)`; a single-axis device is named alone."""
    where = f"{dev.name}.{ax.axis}" if dev.kind.multi_axis else dev.name
    return f"axis {ax.role} ({where})"


def reading_text(detector: Any) -> str:
    """One READ: the power and the range it was taken on (SCPI's no-reading is an answer)."""
    try:
        reading = detector.read()
    except InvalidReading as exc:
        return f"no reading ({exc})"
    over = " (over range)" if reading.saturated else ""
    return f"{reading.power_w:.4e} W on the {reading.range_w:g} W range{over}"


def room_text(sensor: Any) -> str:
    """One reading of an environment sensor: temperature and relative humidity."""
    room = sensor.read_room()
    return f"{room.temperature_c:.1f} degC, {100.0 * room.humidity_rel:.1f} %RH"


def wavelength_answer(subject: str, detector: Any, wavelength_nm: float) -> Answer | None:
    """A problem line when the detector's sensor head cannot take the config's wavelength,
    asked read-only where the detector tells its head's range (a PM100's SENS:CORR:WAV? MIN /
    MAX); None when the range holds it or the detector tells none."""
    if not isinstance(detector, HeadRange):
        return None
    try:
        outside = WavelengthOutsideHead.asked(detector, wavelength_nm)
    except UNANSWERED as exc:
        return Answer(subject, detector.name, str(exc) or type(exc).__name__, False)
    if outside is None:
        return None
    return Answer(subject, detector.name, outside.reason, True, problem=True)


def check_connections(cfg: InstrumentConfig,
                      at_positions: Callable[[dict[str, float]], None] | None = None
                      ) -> ConnectionReport:
    """Open each device, ask its identity, each axis's position, one detector reading,
    whether its head takes the config's wavelength and one environment-sensor reading; close
    everything. at_positions(positions
    by role) is told where the axes stand before the detector is read (the emulated detector
    of `--sim detector` lights itself from it)."""
    closers: list[Callable[[], None]] = []
    opened: dict[str, Any] = {}
    positions: dict[str, float] = {}
    answers: list[Answer] = []

    def identify(dev: DeviceConfig) -> str:
        driver = open_device(dev, closers)
        text = identity_text(driver.identity())
        opened[dev.name] = driver
        return text

    def position(dev: DeviceConfig, ax: AxisConfig) -> str:
        positions[ax.role] = axis_of(dev, ax, opened[dev.name]).position()
        return f"{positions[ax.role]:.5f} deg"

    try:
        for dev in cfg.devices.values():
            answers.append(_asked(device_subject(dev), dev.name, lambda d=dev: identify(d)))
        for ax in cfg.axes.values():
            if ax.device in opened:
                dev = cfg.devices[ax.device]
                answers.append(_asked(axis_subject(dev, ax), dev.name,
                                      lambda d=dev, a=ax: position(d, a)))
        if at_positions is not None:
            at_positions(positions)
        name = cfg.detector.device
        if name in opened:
            answers.append(_asked(f"detector ({name})", name,
                                  lambda: reading_text(opened[name])))
            head = wavelength_answer(f"detector ({name})", opened[name],
                                     cfg.detector.wavelength_nm)
            answers.extend([head] if head is not None else [])
        sensor = cfg.environment
        if sensor in opened:
            answers.append(_asked(f"environment ({sensor})", sensor,
                                  lambda: room_text(opened[sensor])))
    finally:
        close_all(closers)
    return ConnectionReport(answers)
