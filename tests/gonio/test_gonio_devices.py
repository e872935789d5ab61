"""`gonio devices CONFIG` on the emulated benches, and `gonio devices --list`.

Each bench is served in this process (what `gonio emulate` serves), its stages moved and its
settings changed away from the config's through the drivers; `gonio devices` then runs on a
copy of the config pointed at it, in its own process. Its lines must carry each device's
identity and each axis's position, and the emulators' truth (positions, targets, speeds,
limits, the detector's settings) must be what it was: the check moves and sets nothing.
Cost: one bench and two or three `gonio` processes per test (seconds, once the suite's
multiple-scattering tables are cached).
"""

from __future__ import annotations

import os
import re
import sys

import pytest
from gonio_testkit import fast_config, gonio_cli, pointed, serving, write_toml

from gonio.config import load_config
from gonio.connection_check import identity_text
from gonio.instrument import build_instrument
from gonio.port_inventory import stable_names, usb_strings, visa_lines

MOVED_TO = {"sample": 12.5, "arm": 40.0}
AXIS_LINE = re.compile(r"axis (\w+) \(([\w.]+)\): (-?\d+\.\d{5}) deg")
DRIVE_SETTINGS = ("target_position", "velocity", "acceleration", "limit_negative",
                  "limit_positive")
DETECTOR_LINE = re.compile(r"detector \((\w+)\): (\S+) W on the (\S+) W range")


def stage_truth(bench) -> dict:
    """Every emulated axis's position, target, speed, acceleration and limits (a Modbus
    drive's also as its registers hold them: it takes them up at the next move)."""
    truth = {}
    for name, emu in bench.emulators.items():
        for key, axis in getattr(emu, "axes", {}).items():
            truth[name, key] = _motion(axis.motion)
        for unit, emulated in getattr(emu, "units", {}).items():
            if hasattr(emulated, "axis"):
                truth[name, unit] = (_motion(emulated.axis), *(
                    emulated.registers.get(key) for key in DRIVE_SETTINGS))
    return truth


def _motion(m) -> tuple:
    return m.position(), m.target(), m.speed, m.accel, m.limits


def detector_truth(bench, name: str) -> tuple:
    """The emulated detector's wavelength, averaging and range settings."""
    emu = bench.emulators[name]
    if hasattr(emu, "units"):
        unit = next(u for u in emu.units.values() if hasattr(u, "model"))
        return tuple(unit.registers.get(key)
                     for key in ("wavelength", "averaging", "autorange", "gain_range"))
    return emu.wavelength_nm, emu.averaging, emu.autorange, emu.range_w


def leave_bench_off_config(path) -> tuple[dict[str, dict], float]:
    """Move the stages off their power-up places and set speeds, limits and the detector
    (a fixed range: autoranging changes the range in use) away from the config's, as another
    program might leave a bench; the identity each
    device reported, by name, and the detector's range, W."""
    with build_instrument(load_config(path)) as inst:
        for role, target in MOVED_TO.items():
            axis, ax = inst.axes[role], inst.config.axes[role]
            axis.move_to(target)
            axis.wait(10.0)
            lo, hi = ax.limits_deg
            axis.configure(ax.speed_deg_s / 2, ax.accel_deg_s2 / 2, (lo + 1.0, hi - 1.0))
        range_w = inst.detector.full_scales_w()[-1]
        inst.detector.configure(800.0, 2, range_w)
        return {name: record["identity"] for name, record in inst.devices.items()}, range_w


@pytest.mark.parametrize("example", ["sim-serial", "sim-modbus", "sim-zaber", "sim-zaber-chain"])
def test_devices_reports_every_device_and_moves_nothing(tmp_path, example):
    cfg = fast_config(example)
    with serving(write_toml(tmp_path / "served.toml", cfg)) as (endpoints, bench):
        path = write_toml(tmp_path / "bench.toml", pointed(cfg, endpoints))
        identities, range_w = leave_bench_off_config(path)
        config = load_config(path)
        stages, detector = stage_truth(bench), detector_truth(bench, config.detector.device)
        proc = gonio_cli("devices", path)
        assert (stage_truth(bench), detector_truth(bench, config.detector.device)) == \
            (stages, detector)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    assert len(lines) == len(config.devices) + len(config.axes) + 1, proc.stdout
    for name, dev in config.devices.items():
        unit = f", unit {dev.settings['unit']}" if "unit" in dev.settings else ""
        line = next(ln for ln in lines if ln.startswith(f"device {name} "))
        assert line.startswith(f"device {name} ({dev.protocol} at {dev.endpoint}")
        assert unit in line
        assert line.endswith(f"): {identity_text(identities[name])}")
    positions = {m[1]: (m[2], float(m[3])) for m in map(AXIS_LINE.fullmatch, lines) if m}
    for role, ax in config.axes.items():
        where = f"{ax.device}.{ax.axis}" if config.devices[ax.device].kind.multi_axis \
            else ax.device
        assert positions[role][0] == where
        assert positions[role][1] == pytest.approx(MOVED_TO[role], abs=1e-3)
    reading = DETECTOR_LINE.fullmatch(lines[-1])
    assert reading and reading[1] == config.detector.device, lines[-1]
    assert float(reading[3]) == pytest.approx(range_w)
    assert abs(float(reading[2])) < range_w


def test_device_that_cannot_be_opened_is_one_line_and_the_others_are_still_asked(tmp_path):
    cfg = fast_config("sim-serial")
    with serving(write_toml(tmp_path / "served.toml", cfg)) as (endpoints, _bench):
        bench = pointed(cfg, endpoints)
        missing = tmp_path / "no-such-port"
        bench["devices"]["esp"]["port"] = str(missing)
        proc = gonio_cli("devices", write_toml(tmp_path / "bench.toml", bench))
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert "Traceback" not in proc.stderr
    lines = proc.stdout.splitlines()
    assert lines[0].startswith(f"device esp (esp at {missing}): did not answer: ")
    assert str(missing) in lines[0].split("did not answer: ")[1]
    assert lines[1].startswith(f"device pm100 (pm100 at {endpoints['pm100'][1]}): idn: ")
    assert DETECTOR_LINE.fullmatch(lines[2]), lines  # the esp's axes are not asked
    assert len(lines) == 3
    assert proc.stderr.splitlines() == ["gonio devices: 1 of 2 devices did not answer: esp"]


def test_devices_sim_asks_the_emulators(tmp_path):
    proc = gonio_cli("devices", "--sim", write_toml(tmp_path / "z.toml", fast_config("sim-zaber")))
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    assert lines[0].startswith("device zaber (zaber at /dev/pts/")
    assert "device_id: " in lines[0] and "firmware: " in lines[0]
    assert [m[1] for m in map(AXIS_LINE.fullmatch, lines) if m] == ["sample", "arm"]
    assert DETECTOR_LINE.fullmatch(lines[-1])


def test_emulated_detector_reads_the_light_where_the_real_stages_stand(tmp_path):
    """`--sim pm100` beside served (here: real) ESP stages at the [beam] place: the emulated
    meter is told where they stand before it reads, so it sees the direct beam."""
    cfg = fast_config("sim-serial")
    with serving(write_toml(tmp_path / "served.toml", cfg)) as (endpoints, bench):
        every = write_toml(tmp_path / "served-pointed.toml", pointed(cfg, endpoints))
        with build_instrument(load_config(every)) as inst:
            for role, target in (("sample", 90.0), ("arm", 180.0)):
                inst.axes[role].move_to(target)
                inst.axes[role].wait(10.0)
        esp_served = pointed(cfg, {"esp": endpoints["esp"]})
        proc = gonio_cli("devices", write_toml(tmp_path / "bench.toml", esp_served),
                         "--sim", "pm100")
    assert proc.returncode == 0, proc.stderr
    reading = DETECTOR_LINE.fullmatch(proc.stdout.splitlines()[-1])
    assert reading, proc.stdout
    assert float(reading[2]) > 0.5 * cfg["sim"]["source"]["power_w"]  # the whole beam


@pytest.mark.parametrize("sensor, fit", [("S120C", False), ("S122C", True)])
def test_a_head_that_cannot_take_the_wavelength_is_a_device_problem(tmp_path, sensor, fit):
    """1550 nm in [optics]: a silicon S120C (400-1100 nm) cannot measure there, a germanium
    S122C can; asked read-only, the meter's wavelength stays as it was left."""
    cfg = fast_config()
    cfg["optics"]["wavelength_nm"] = 1550.0
    cfg["sim"]["devices"] = {"pm100": {"sensor": sensor}}
    with serving(write_toml(tmp_path / "served.toml", cfg)) as (endpoints, bench):
        before = detector_truth(bench, "pm100")
        proc = gonio_cli("devices", write_toml(tmp_path / "bench.toml",
                                               pointed(cfg, endpoints)))
        # (wavelength, averaging, autorange): the range in use follows the light
        assert detector_truth(bench, "pm100")[:3] == before[:3] and before[0] != 1550.0
    lines = proc.stdout.splitlines()
    assert DETECTOR_LINE.fullmatch(lines[-1 if fit else -2]), proc.stdout
    if fit:
        assert proc.returncode == 0, proc.stderr
        return
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert lines[-1] == ("detector (pm100): wavelength 1550 nm is outside the sensor head "
                         "S120C's range 400-1100 nm")
    assert proc.stderr.splitlines() == ["gonio devices: cannot measure as configured: pm100"]


def test_list_shows_every_serial_port_and_the_visa_resources():
    from pyvisa_py.serial import SerialSession
    from serial.tools import list_ports

    proc = gonio_cli("devices", "--list")
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    assert lines[0] == "serial ports (pyserial):"
    names = stable_names()
    for port in list_ports.comports():
        shown = names.get(os.path.realpath(port.device), port.device)
        assert any(ln.startswith(f'  port = "{shown}"') for ln in lines), (port.device, lines)
    assert "VISA resources (pyvisa-py: ASRL and USB INSTR):" in lines
    for resource in SerialSession.list_resources():
        assert f'  resource = "{resource}"' in lines


def test_list_without_pyvisa_says_how_to_install_it(monkeypatch):
    monkeypatch.setitem(sys.modules, "pyvisa", None)  # what `import pyvisa` meets without it
    assert visa_lines() == ["VISA: pyvisa not installed (pip install gonio[visa])"]


def test_stable_names_map_a_port_to_its_by_id_link(tmp_path):
    leader, follower = os.openpty()
    try:
        link = tmp_path / "usb-Thorlabs_PM100USB-if00"
        link.symlink_to(os.ttyname(follower))
        assert stable_names(tmp_path) == {os.path.realpath(os.ttyname(follower)): str(link)}
    finally:
        os.close(leader)
        os.close(follower)
    assert stable_names(tmp_path / "absent") == {}


def test_usb_strings_come_from_the_device_with_those_ids_and_serial(tmp_path):
    for folder, ids in (("1-1", ("1313", "8072", "P2000000")), ("1-2", ("1313", "8072", "P1")),
                        ("1-1:1.0", None)):
        (tmp_path / folder).mkdir()
        if ids:
            for key, value in zip(("idVendor", "idProduct", "serial"), ids, strict=True):
                (tmp_path / folder / key).write_text(value + "\n")
            (tmp_path / folder / "manufacturer").write_text("Thorlabs\n")
            (tmp_path / folder / "product").write_text(f"PM100USB {folder}\n")
    assert usb_strings(0x1313, 0x8072, "P2000000", tmp_path) == ("Thorlabs", "PM100USB 1-1")
    assert usb_strings(0x1313, 0x8078, "P2000000", tmp_path) == (None, None)
    assert usb_strings(0x1313, 0x8072, "P2000000", tmp_path / "absent") == (None, None)


@pytest.mark.parametrize("args, message", [
    ((), "a CONFIG file is needed (or --list)"),
    (("--list", "examples/instruments/sim-serial.toml"), "--list takes no CONFIG and no --sim"),
])
def test_devices_usage_errors_are_one_line(args, message):
    proc = gonio_cli("devices", *args)
    assert proc.returncode == 2
    assert proc.stderr == f"gonio devices: error: {message}\n"
