"""The ESP301 manual's command summary (EDH0235En1030, section 3.6), with what the emulator does.

One entry per mnemonic of the summary: its meaning as the summary gives it and, for a command
the emulator does not model, why. The emulator refuses such a command with error 27 COMMAND
NOT ALLOWED (it exists on the real controller, so it is never error 6); docs/devices.md's
command table lists the same entries (tests/devices_serial/test_esp_manual_commands.py).
"""

from __future__ import annotations

from dataclasses import dataclass

NO_DIO = "no digital I/O port is emulated"
NO_PROGRAMS = "stored programs are not emulated (a host script drives the bench)"
NO_ACQUISITION = "no data acquisition is emulated"
NO_GROUPS = "no multi-axis group (interpolated) motion is emulated"
NO_MASTER_SLAVE = "no master-slave axis coupling is emulated"


@dataclass(frozen=True)
class ManualCommand:
    """A command of the manual's summary: what it does and, if not emulated, why not."""

    meaning: str
    not_emulated: str | None = None

    @property
    def emulated(self) -> bool:
        """True when the emulator implements the command."""
        return self.not_emulated is None


def _summary() -> dict[str, ManualCommand]:
    """The summary as {mnemonic: ManualCommand}, alphabetical."""
    c = ManualCommand
    table = {
        "AB": c("abort motion"),
        "AC": c("set acceleration"),
        "AE": c("set e-stop deceleration"),
        "AF": c("acceleration/deceleration feed-forward gain"),
        "AG": c("set deceleration"),
        "AU": c("set maximum acceleration"),
        "BA": c("set backlash compensation"),
        "BG": c("assign DIO bits to execute stored programs", NO_DIO),
        "BK": c("assign DIO bits to inhibit motion", NO_DIO),
        "BL": c("enable DIO bits to inhibit motion", NO_DIO),
        "BM": c("assign DIO bits to notify motion status", NO_DIO),
        "BN": c("enable DIO bits to notify motion status", NO_DIO),
        "BO": c("set DIO port direction", NO_DIO),
        "BP": c("assign DIO for jog mode", NO_DIO),
        "BQ": c("enable/disable DIO jog mode", NO_DIO),
        "CL": c("set closed loop update interval"),
        "CO": c("set linear compensation"),
        "DB": c("set position deadband"),
        "DC": c("setup data acquisition", NO_ACQUISITION),
        "DD": c("get data acquisition done status", NO_ACQUISITION),
        "DE": c("enable/disable data acquisition", NO_ACQUISITION),
        "DF": c("get data acquisition sample count", NO_ACQUISITION),
        "DG": c("get acquisition data", NO_ACQUISITION),
        "DH": c("define home"),
        "DL": c("define label", NO_PROGRAMS),
        "DO": c("set DAC offset", "no DAC output is emulated"),
        "DP": c("get target position"),
        "DV": c("get working speed"),
        "EO": c("automatic execution on power on", NO_PROGRAMS),
        "EP": c("enter program download mode", NO_PROGRAMS),
        "EX": c("execute stored program", NO_PROGRAMS),
        "FE": c("set following error threshold"),
        "FP": c("set position display resolution"),
        "FR": c("full step resolution"),
        "GR": c("set master-slave gear ratio", NO_MASTER_SLAVE),
        "HA": c("set group acceleration", NO_GROUPS),
        "HB": c("read list of groups assigned", NO_GROUPS),
        "HC": c("move group along an arc", NO_GROUPS),
        "HD": c("set group deceleration", NO_GROUPS),
        "HE": c("set group e-stop deceleration", NO_GROUPS),
        "HF": c("group motor power off", NO_GROUPS),
        "HJ": c("set group jerk", NO_GROUPS),
        "HL": c("move group along a line", NO_GROUPS),
        "HN": c("create new group", NO_GROUPS),
        "HO": c("group motor power on", NO_GROUPS),
        "HP": c("get group position", NO_GROUPS),
        "HQ": c("wait for group via point buffer near empty", NO_GROUPS),
        "HS": c("stop group motion", NO_GROUPS),
        "HV": c("set group velocity", NO_GROUPS),
        "HW": c("wait for group motion to stop", NO_GROUPS),
        "HX": c("delete a group", NO_GROUPS),
        "HZ": c("get group size", NO_GROUPS),
        "ID": c("get stage model and serial number"),
        "JH": c("set jog high speed"),
        "JK": c("set jerk rate"),
        "JL": c("jump to label", NO_PROGRAMS),
        "JW": c("set jog low speed"),
        "KD": c("set derivative gain Kd"),
        "KI": c("set integral gain Ki"),
        "KP": c("set proportional gain Kp"),
        "KS": c("set saturation coefficient Ks"),
        "LC": c("lock/unlock keyboard", "no front panel is emulated"),
        "LP": c("list program", NO_PROGRAMS),
        "MD": c("get axis motion status"),
        "MF": c("power off"),
        "MO": c("power on"),
        "MT": c("move to hardware travel limit",
                "no limit switches are emulated (the software limits bound the travel)"),
        "MV": c("move indefinitely"),
        "MZ": c("move to nearest index", "no encoder index is emulated"),
        "OH": c("set home search high speed"),
        "OL": c("set home search low speed"),
        "OM": c("set home search mode"),
        "OR": c("origin searching"),
        "PA": c("move absolute"),
        "PH": c("get hardware status",
                "no limit, home or amplifier signals are emulated to report"),
        "PR": c("move relative"),
        "QD": c("update Unidriver amplifier"),
        "QG": c("set gear constant"),
        "QI": c("motor current"),
        "QM": c("define motor type"),
        "QP": c("quit program mode", NO_PROGRAMS),
        "QR": c("torque reduction",
                "its two-value reply format was not at hand in the manual"),
        "QS": c("set microstep factor"),
        "QT": c("define tachometer constant"),
        "QV": c("set motor voltage"),
        "RQ": c("generate service request", "a GPIB service request; the emulator is serial"),
        "RS": c("reset the controller",
                "a reset reboots and reloads flash; restart the emulator instead"),
        "SA": c("set device address", "a GPIB address; the emulator is serial"),
        "SB": c("set DIO state", NO_DIO),
        "SH": c("set home preset position"),
        "SI": c("set master-slave jog update interval", NO_MASTER_SLAVE),
        "SK": c("set slave axis jog velocity coefficients", NO_MASTER_SLAVE),
        "SL": c("set left limit"),
        "SM": c("save to non-volatile memory"),
        "SN": c("set units"),
        "SR": c("set right limit"),
        "SS": c("set master-slave relationship", NO_MASTER_SLAVE),
        "ST": c("stop motion"),
        "SU": c("set encoder resolution"),
        "TB": c("get error message"),
        "TE": c("get error number"),
        "TJ": c("set trajectory mode"),
        "TP": c("get position"),
        "TS": c("get controller status",
                "its status-byte bit table was not at hand in the manual"),
        "TV": c("get velocity"),
        "TX": c("get controller activity",
                "its activity-byte bit table was not at hand in the manual"),
        "UF": c("update filter parameters"),
        "UH": c("wait for DIO bit high", NO_DIO),
        "UL": c("wait for DIO bit low", NO_DIO),
        "VA": c("set velocity"),
        "VB": c("set base velocity for step motors"),
        "VE": c("get firmware version"),
        "VF": c("set velocity feed-forward gain"),
        "VU": c("set maximum speed"),
        "WP": c("wait for absolute position crossing"),
        "WS": c("wait for stop"),
        "WT": c("wait for time"),
        "XM": c("get available program memory", NO_PROGRAMS),
        "XX": c("delete a stored program", NO_PROGRAMS),
        "ZA": c("set amplifier configuration"),
        "ZB": c("set feedback configuration"),
        "ZE": c("set e-stop configuration"),
        "ZF": c("set following error configuration"),
        "ZH": c("set hardware limit configuration"),
        "ZS": c("set software limit configuration"),
        "ZU": c("get ESP system configuration",
                "its stage/driver detection word was not at hand in the manual"),
        "ZZ": c("set system configuration",
                "system-wide fault and event handling is not emulated"),
    }
    return dict(sorted(table.items()))


COMMAND_SUMMARY: dict[str, ManualCommand] = _summary()
