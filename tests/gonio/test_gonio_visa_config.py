"""A line device (ESP, PM100, Zaber) reached by a VISA `resource` instead of a `port`, and the
line settings as config keys: one clear error for each bad value, the settings applied to the
real line (a pty's termios, opened as a port and as an ASRL resource), and the emulated bench
serving a device given by resource on the link the resource names."""

import os
import re
import termios
from contextlib import contextmanager

import pytest
from gonio_testkit import (
    EXAMPLES,
    AbortAfter,
    emulating,
    fast_config,
    gonio_cli,
    load_example,
    run_dir_of,
    write_plan,
    write_toml,
)

from drivers.esp import DECIMALS
from drivers.pm100 import NR3_DECIMALS, Pm100
from gonio.config import parse_config
from gonio.device_kinds import KINDS, endpoint_keys
from gonio.errors import ConfigError
from gonio.instrument import build_instrument
from gonio.runner import new_scan
from gonio.simulate import simulation
from gonio.store import open_run

USB_METER = "USB0::0x1313::0x8072::P2000000::INSTR"  # a PM100USB as a lab names it
ASRL = r"ASRL/dev/pts/\d+::INSTR"
SOCKET = r"TCPIP0::127\.0\.0\.1::\d+::SOCKET"
SMALL_PLAN = {"name": "visa-small", "averaging": 1,
              "grid": [{"theta_i_deg": [10.0], "theta_o_deg": [20.0, 30.0, 40.0]}]}


def config_with(device: str, name: str = "sim-serial", drop: tuple[str, ...] = (), **keys):
    """An example config whose device has `keys` set and the keys in `drop` removed."""
    cfg = fast_config(name)
    table = cfg["devices"][device]
    for key in drop:
        del table[key]
    table.update(keys)
    return cfg


@pytest.mark.parametrize("keys, drop, how", [
    ({"resource": USB_METER}, (), "not both"),
    ({}, ("port",), "none is given"),
])
def test_a_device_has_a_port_or_a_resource_never_both_nor_neither(keys, drop, how):
    for kind in ("esp", "pm100"):
        with pytest.raises(ConfigError) as err:
            parse_config(config_with(kind, drop=drop, **keys))
        assert str(err.value) == (f"config: [devices.{kind}]: give exactly one of 'port' or "
                                  f"'resource' (a serial port or a VISA resource string); {how}")
    with pytest.raises(ConfigError, match=r"^config: \[devices\.zaber\]: give exactly one of "):
        parse_config(config_with("zaber", "sim-zaber", drop=drop, **keys))


@pytest.mark.parametrize("device, key, value, message", [
    ("pm100", "parity", "bogus", "must be one of none, even, odd, mark, space; got 'bogus'"),
    ("pm100", "parity", "EVEN", "must be one of none, even, odd, mark, space; got 'EVEN'"),
    ("esp", "stopbits", 3, "must be one of 1, 1.5, 2; got 3"),
    ("esp", "stopbits", "2", "must be a number, got '2'"),
    ("esp", "rtscts", "yes", "must be true or false, got 'yes'"),
    ("pm100", "xonxoff", 1, "must be true or false, got 1"),
    ("esp", "decimals", 0, "must be in [1, 10], got 0"),
    ("esp", "decimals", "5", "must be an integer, got '5'"),
    ("pm100", "nr3_decimals", 2.5, "must be an integer, got 2.5"),
    ("pm100", "nr3_decimals", 15, "must be in [1, 14], got 15"),
    ("pm100", "baudrate", 0, "must be in [1, 4e+06], got 0"),
    ("pm100", "resource", 5, "must be a string, got 5"),
])
def test_each_bad_line_setting_is_one_error_naming_it(device, key, value, message):
    drop = ("port",) if key == "resource" else ()
    with pytest.raises(ConfigError) as err:
        parse_config(config_with(device, drop=drop, **{key: value}))
    assert str(err.value) == f"config: [devices.{device}] {key}: {message}"


def test_a_setting_of_another_kind_is_refused():
    with pytest.raises(ConfigError, match=r"^config: \[devices\.pm100\]: unknown key "
                                          r"'decimals'"):
        parse_config(config_with("pm100", decimals=5))


def test_the_config_defaults_are_the_drivers():
    defaults = {kind: {s.key: s.default for s in KINDS[kind].settings}
                for kind in ("esp", "pm100", "zaber")}
    assert defaults["esp"]["decimals"] == DECIMALS and defaults["esp"]["rtscts"] is True
    assert defaults["pm100"]["nr3_decimals"] == NR3_DECIMALS
    for kind in defaults.values():
        assert (kind["parity"], kind["stopbits"], kind["xonxoff"]) == ("none", 1, False)
    assert defaults["zaber"]["baudrate"] == 115200 and defaults["zaber"]["rtscts"] is False


def test_a_resource_is_the_devices_endpoint_and_may_change_on_resume():
    cfg = parse_config(config_with("pm100", drop=("port",), resource=USB_METER))
    meter = cfg.devices["pm100"]
    assert meter.endpoint == USB_METER and "port" not in meter.settings
    served = "TCPIP0::127.0.0.1::5025::SOCKET"
    assert meter.endpoint_values(served) == {"resource": served}
    assert {"port", "resource"} <= set(endpoint_keys())


def termios_of(path: str) -> list:
    fd = os.open(path, os.O_RDWR | os.O_NOCTTY)
    try:
        return termios.tcgetattr(fd)
    finally:
        os.close(fd)


@contextmanager
def opened_bench(cfg: dict):
    """The emulated bench of a config and the instrument opened on it."""
    with simulation(parse_config(cfg)) as sim, build_instrument(sim.config, sim.time_scale):
        yield sim.config


@pytest.mark.parametrize("reached_by", ["port", "asrl-resource"])
def test_line_settings_reach_the_line(reached_by):
    # a pty keeps 8 data bits and no parity whatever it is asked (parity is a real adaptor's):
    # the settings checked are those a pty keeps
    line = {"stopbits": 2, "xonxoff": True, "rtscts": False}
    meter = ({} if reached_by == "port" else
             {"resource": "ASRL/dev/ttyUSB1::INSTR"})
    cfg = config_with("pm100", drop=() if reached_by == "port" else ("port",), **line, **meter)
    cfg["devices"]["esp"]["rtscts"] = False
    with opened_bench(cfg) as pointed:
        endpoint = pointed.devices["pm100"].endpoint
        path = endpoint if reached_by == "port" else re.fullmatch(r"ASRL(.+)::INSTR",
                                                                  endpoint).group(1)
        iflag, _, cflag, *_ = termios_of(path)
        assert cflag & termios.CSTOPB and iflag & termios.IXON and iflag & termios.IXOFF
        assert not cflag & termios.CRTSCTS
        assert not termios_of(pointed.devices["esp"].endpoint)[2] & termios.CRTSCTS
    with opened_bench(fast_config()) as pointed:  # the defaults: 8N1, the ESP on RTS/CTS
        _, _, meter_cflag, *_ = termios_of(pointed.devices["pm100"].endpoint)
        assert not meter_cflag & (termios.CSTOPB | termios.CRTSCTS)
        assert termios_of(pointed.devices["esp"].endpoint)[2] & termios.CRTSCTS


@pytest.mark.parametrize("resource, served", [
    (USB_METER, ASRL),
    ("ASRL/dev/ttyUSB1::INSTR", ASRL),
    ("TCPIP0::192.0.2.7::5025::SOCKET", SOCKET),
    ("tcpip::meter.lab::5025::socket", SOCKET),  # VISA resource names ignore case
])
def test_the_emulated_bench_serves_the_link_a_resource_names(resource, served):
    with opened_bench(config_with("pm100", drop=("port",), resource=resource)) as pointed:
        assert re.fullmatch(served, pointed.devices["pm100"].endpoint)


def test_gonio_emulate_prints_the_resource_it_serves():
    with emulating(EXAMPLES / "instruments" / "sim-visa.toml") as endpoints:
        protocol, resource = endpoints["pm100"]
        assert protocol == "pm100" and re.fullmatch(ASRL, resource)
        assert not endpoints["esp"][1].startswith("ASRL")  # the ESP is given by its port
        with Pm100(resource=resource, timeout_s=2.0) as meter:
            assert meter.idn.startswith("Thorlabs,") and meter.read().power_w >= 0.0


def test_the_demo_scan_runs_with_the_meter_configured_by_resource(tmp_path):
    proc = gonio_cli("scan", EXAMPLES / "plans" / "demo.toml", "--instrument",
                     EXAMPLES / "instruments" / "sim-visa.toml", "--sim", "--no-plot",
                     "--out", tmp_path)
    assert proc.returncode == 0, proc.stderr
    run = open_run(run_dir_of(proc))
    assert run.meta["status"] == "completed" and len(run) == run.meta["planned"] == 72
    meter = run.meta["sessions"][-1]["devices"]["pm100"]
    assert re.fullmatch(ASRL, meter["endpoint"])
    assert meter["identity"]["idn"].startswith("Thorlabs,")
    assert load_example("sim-visa")["devices"]["pm100"]["resource"] == USB_METER


def test_a_scan_reaches_the_meter_over_tcpip_socket(tmp_path):
    cfg = config_with("pm100", "sim-visa", resource="TCPIP0::192.0.2.7::5025::SOCKET")
    proc = gonio_cli("scan", write_plan(tmp_path, SMALL_PLAN, cfg), "--sim", "--no-plot",
                     "--out", tmp_path)
    assert proc.returncode == 0, proc.stderr
    run = open_run(run_dir_of(proc))
    assert run.meta["status"] == "completed" and len(run) == run.meta["planned"]
    assert re.fullmatch(SOCKET, run.meta["sessions"][-1]["devices"]["pm100"]["endpoint"])


def test_a_run_started_on_a_port_resumes_with_the_meter_given_by_resource(tmp_path):
    cfg = fast_config()
    plan = write_plan(tmp_path, SMALL_PLAN, cfg)
    started = new_scan(plan, sim=True, out=tmp_path / "runs", progress=False,
                       control=AbortAfter(2))
    assert started.outcome.status == "aborted"
    by_resource = config_with("pm100", drop=("port",), resource=USB_METER)
    moved = write_toml(tmp_path / "moved.toml", by_resource)
    proc = gonio_cli("scan", "--resume", started.path, "--instrument", moved, "--no-plot",
                     "--no-progress")
    assert proc.returncode == 0, proc.stderr
    run = open_run(started.path)
    assert run.meta["status"] == "completed" and len(run) == run.meta["planned"]
    session = run.meta["sessions"][-1]
    assert session["endpoint_changes"] == {
        "devices.pm100.port": {"from": cfg["devices"]["pm100"]["port"], "to": None},
        "devices.pm100.resource": {"from": None, "to": USB_METER}}
    assert re.fullmatch(ASRL, session["devices"]["pm100"]["endpoint"])
