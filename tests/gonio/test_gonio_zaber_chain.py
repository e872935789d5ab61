"""Two Zaber devices on one daisy chain (examples/instruments/sim-zaber-chain.toml: the sample
stage at address 1 and the arm stage at address 2, one port): the emulated bench serves them
as one chain on one pty, `gonio devices` and `gonio scan --sim` open the port once for both
(every device answers, no reading retried), line settings that differ between the devices of
one chain are one config error naming both, and a chain the emulators cannot serve as one
(only part of it emulated, faults or products given apart) is one error naming two devices.
A chain's port written once as a /dev/serial/by-id symlink and once as its device file is
one chain, to the config check and to the emulators."""

from pathlib import Path

import pytest
from gonio_testkit import (
    completed_unretried,
    fast_config,
    gonio_cli,
    one_line_error,
    write_plan,
    write_toml,
)

from gonio.config import parse_config
from gonio.errors import ConfigError
from gonio.simulate import simulation
from sim.devices.photodiode import SimConfigError
from sim.emulate import start

EXAMPLE = "sim-zaber-chain"
PLAN = {"name": "chain", "averaging": 1, "dark": {"every": 4}, "beam": {"every": 4}, "grid": [
    {"side": "reflection", "theta_i_deg": [20.0], "theta_o_deg": [-50.0, -10.0, 35.0]}]}
STAGES = ("sample_stage", "arm_stage")


def identity_line(name: str, endpoint: str, address: int) -> str:
    return (f"device {name} (zaber at {endpoint}): device_id: 50001; serial: "
            f"{120000 + address}; firmware: 7.38; address: {address}")


def test_the_emulated_bench_serves_the_chain_on_one_pty():
    with start(fast_config(EXAMPLE), devices=list(STAGES)) as bench:
        sample, arm = (bench.endpoints[name] for name in STAGES)
        assert sample.endpoint == arm.endpoint and sample.endpoint.startswith("/dev/pts/")
        chain = bench.emulators["sample_stage"]
        assert bench.emulators["arm_stage"] is chain
        assert sorted(chain.axes) == [(1, 1), (2, 1)]  # each device at its address, axis 1
        assert [line.split()[:2] for line in (sample.line, arm.line)] == [
            ["sample_stage", "zaber"], ["arm_stage", "zaber"]]


def test_gonio_devices_sim_opens_the_port_once_for_both(tmp_path):
    proc = gonio_cli("devices", "--sim", write_toml(tmp_path / "chain.toml",
                                                   fast_config(EXAMPLE)))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    lines = proc.stdout.splitlines()
    endpoint = lines[0].split(" at ", 1)[1].split(")", 1)[0]
    assert lines[:2] == [identity_line("sample_stage", endpoint, 1),
                         identity_line("arm_stage", endpoint, 2)]
    assert lines[3:5] == ["axis sample (sample_stage.1): 0.00000 deg",
                          "axis arm (arm_stage.1): 6.00000 deg"]
    assert lines[5].startswith("detector (pm100): ") and len(lines) == 6
    assert "in use" not in proc.stdout + proc.stderr


def test_a_scan_on_the_chain_completes_with_no_reading_retried(tmp_path):
    plan = write_plan(tmp_path, PLAN, fast_config(EXAMPLE))
    proc = gonio_cli("scan", plan, "--sim", "--out", tmp_path / "runs", "--no-plot",
                     "--no-progress")
    run = completed_unretried(proc)
    session = run.meta["sessions"][0]
    devices = session["devices"]
    assert devices["sample_stage"]["endpoint"] == devices["arm_stage"]["endpoint"]
    assert [devices[name]["identity"]["address"] for name in STAGES] == ["1", "2"]
    assert [devices[name]["identity"]["serial"] for name in STAGES] == ["120001", "120002"]
    assert session["lines"]["sample_stage"]["resyncs"] == 0  # the chain's one line


LINE = "both are on the chain at /dev/ttyUSB0, one line with one setting"


@pytest.mark.parametrize("key, value, message", [
    ("baudrate", 9600, f"9600 differs from [devices.sample_stage]'s 115200: {LINE}"),
    ("timeout_s", 0.5, f"0.5 differs from [devices.sample_stage]'s 1.0: {LINE}"),
    ("parity", "even", f'"even" differs from [devices.sample_stage]\'s "none": {LINE}'),
])
def test_a_chains_devices_that_disagree_are_one_config_error_naming_both(key, value, message):
    with pytest.raises(ConfigError) as err:
        parse_config(fast_config(EXAMPLE, arm_stage={key: value}))
    assert str(err.value) == f"config: [devices.arm_stage] {key}: {message}"


def test_two_devices_of_a_chain_at_one_address_are_one_config_error_naming_both():
    with pytest.raises(ConfigError) as err:
        parse_config(fast_config(EXAMPLE, arm_stage={"address": 1}))
    assert str(err.value) == ("config: [devices.sample_stage] port and [devices.arm_stage] port "
                              "both reach /dev/ttyUSB0 at address 1")


def test_the_config_error_is_one_line_before_any_device_is_opened(tmp_path):
    path = write_toml(tmp_path / "chain.toml", fast_config(EXAMPLE, arm_stage={"baudrate": 9600}))
    proc = gonio_cli("devices", path)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert proc.stdout == ""
    assert one_line_error(proc.stderr) == (
        f"gonio devices: error: {path}: [devices.arm_stage] baudrate: 9600 differs from "
        f"[devices.sample_stage]'s 115200: {LINE}")


def test_a_separate_port_is_a_device_of_its_own():
    cfg = fast_config(EXAMPLE, arm_stage={"port": "/dev/ttyUSB2", "baudrate": 9600})
    assert parse_config(cfg).devices["arm_stage"].settings["baudrate"] == 9600


@pytest.mark.parametrize("change, devices, message", [
    ({}, ["sample_stage", "pm100"], "sample_stage and arm_stage are one zaber chain "
                                     "(/dev/ttyUSB0): emulate both or neither"),
    ({"faults": {"arm_stage": {"drop_prob": 0.1}}}, None,
     "[sim.faults.arm_stage]: arm_stage is on one chain with sample_stage (/dev/ttyUSB0): one "
     "line, whose faults are [sim.faults.sample_stage]"),
    ({"devices": {"sample_stage": {"device_id": 50419}, "arm_stage": {"device_id": 50420}}},
     None, "[sim.devices.arm_stage]: arm_stage is on one chain with sample_stage "
           "(/dev/ttyUSB0): one emulated product, unlike [sim.devices.sample_stage]"),
])
def test_a_chain_the_emulators_cannot_serve_as_one_is_one_error(change, devices, message):
    cfg = fast_config(EXAMPLE)
    cfg["sim"].update(change)
    with pytest.raises(SimConfigError) as err:
        start(cfg, devices=devices)
    assert str(err.value) == message


def test_one_product_table_given_for_one_device_is_the_chains():
    cfg = fast_config(EXAMPLE)
    cfg["sim"]["devices"] = {"arm_stage": {"device_id": 50419}}
    with start(cfg, devices=list(STAGES)) as bench:
        chain = bench.emulators["arm_stage"]
        assert [chain.devices[n].get("deviceid") for n in (1, 2)] == ["50419", "50419"]


def chain_by_id(alias: Path, **arm_stage) -> dict:
    """The chain with its arm stage's port written as `alias`, a /dev/serial/by-id symlink to
    the sample stage's device file (one port, written two ways)."""
    cfg = fast_config(EXAMPLE)
    if not alias.is_symlink():
        alias.symlink_to(cfg["devices"]["sample_stage"]["port"])
    cfg["devices"]["arm_stage"].update(port=str(alias), **arm_stage)
    return cfg


def test_a_chain_written_by_symlink_and_device_file_is_one_chain(tmp_path):
    alias = tmp_path / "usb-Zaber_Technologies_Inc._X-RSW60A-if00-port0"
    with pytest.raises(ConfigError) as err:
        parse_config(chain_by_id(alias, timeout_s=2.0))
    assert str(err.value) == ("config: [devices.arm_stage] timeout_s: 2.0 differs from "
                              f"[devices.sample_stage]'s 1.0: {LINE}")
    with simulation(parse_config(chain_by_id(alias)), list(STAGES)) as sim:
        assert sim.bench.emulators["arm_stage"] is sim.bench.emulators["sample_stage"]
        sample, arm = (sim.config.devices[name].endpoint for name in STAGES)
        assert sample == arm and sample.startswith("/dev/pts/")
