"""Where emulators listen. A config's Modbus hosts are the real devices' addresses, so a
wildcard listen address there (0.0.0.0, ::) is refused with one line; `gonio emulate` listens
on 127.0.0.1 unless `--bind HOST` says otherwise, and then warns that the devices are open
to the network."""

import os
import signal
import socket
import subprocess
import sys

import pytest
from gonio_testkit import ROOT, fast_config, gonio_cli, one_line_error, write_toml
from pymodbus.client import ModbusTcpClient

from gonio.config import parse_config
from gonio.errors import ConfigError
from gonio_cli.main import main


def own_address() -> str | None:
    """A non-loopback IPv4 address of this machine (the default route's), if it has one."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        try:
            probe.connect(("192.0.2.1", 9))  # TEST-NET-1: picks a route, sends nothing
        except OSError:
            return None
        address = probe.getsockname()[0]
    return None if address.startswith("127.") else address


def answers_modbus(host: str, port: int) -> bool:
    """True if a pymodbus client at host:port reads the sample drive's position."""
    client = ModbusTcpClient(host, port=port, timeout=1, retries=0)
    try:
        return client.connect() and not client.read_holding_registers(
            8, count=2, device_id=1).isError()
    finally:
        client.close()


def emulate(path, *extra) -> tuple[dict[str, str], bool | None, str]:
    """Run `gonio emulate PATH EXTRA` and check the Modbus TCP devices answer on loopback;
    returns the endpoints by device, whether they answer at the machine's own address (None:
    it has none) and stderr."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, "-m", "gonio_cli", "emulate", str(path), *extra],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        endpoints = {}
        for _ in range(3):  # NAME PROTOCOL ENDPOINT
            name, _, endpoint = proc.stdout.readline().split()
            endpoints[name] = endpoint
        port = endpoints["sample_drive"].rsplit(":", 1)[1]
        assert answers_modbus("127.0.0.1", int(port))
        address = own_address()
        reached = None if address is None else answers_modbus(address, int(port))
    finally:
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=20)
    assert proc.returncode == 0, err
    return endpoints, reached, err


@pytest.mark.parametrize("host", ["0.0.0.0", "::", " "])
def test_a_wildcard_device_host_is_refused(host):
    cfg = fast_config("sim-modbus")
    cfg["devices"]["sample_drive"]["host"] = host
    with pytest.raises(ConfigError, match=r"^config: \[devices\.sample_drive\] host: .* is a "
                                          r"listen address, not a device's; emulators listen on "
                                          r"127\.0\.0\.1 \(gonio emulate --bind HOST"):
        parse_config(cfg)


def test_emulate_listens_on_loopback_unless_bound_elsewhere_with_a_warning(tmp_path):
    path = write_toml(tmp_path / "modbus.toml", fast_config("sim-modbus"))
    local, reached, err = emulate(path)
    assert local["sample_drive"].startswith("127.0.0.1:") and err == ""
    assert reached in (None, False)
    opened, reached, err = emulate(path, "--bind", "0.0.0.0")
    assert opened["sample_drive"].startswith("0.0.0.0:")
    assert reached in (None, True)
    assert err.strip() == ("gonio emulate: warning: --bind 0.0.0.0: sample_drive, arm_drive "
                           "listen beyond this machine: anyone who can reach it can move the "
                           "stages and read the detector")


def test_bad_or_useless_bind_is_one_line(tmp_path, capsys):
    modbus = write_toml(tmp_path / "modbus.toml", fast_config("sim-modbus"))
    assert main(["emulate", str(modbus), "--bind", "198.51.100.1"]) == 2  # no such interface
    assert one_line_error(capsys.readouterr().err).startswith(
        "gonio emulate: error: --bind 198.51.100.1: cannot listen there (")
    serial = write_toml(tmp_path / "serial.toml", fast_config("sim-serial"))
    proc = gonio_cli("emulate", serial, "--bind", "0.0.0.0")
    assert proc.returncode == 2 and one_line_error(proc.stderr).endswith(
        "has no Modbus TCP device (serial and RTU devices are ptys, local only)")


def test_a_meter_given_a_socket_resource_listens_where_bind_says_with_a_warning(tmp_path):
    """A line device given a TCPIP SOCKET resource is served on TCP too: --bind applies to it
    and warns about it, as it does to a Modbus TCP device."""
    cfg = fast_config()
    del cfg["devices"]["pm100"]["port"]
    cfg["devices"]["pm100"]["resource"] = "TCPIP0::192.0.2.7::5025::SOCKET"
    path = write_toml(tmp_path / "socket.toml", cfg)
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, "-m", "gonio_cli", "emulate", str(path), "--bind",
                             "0.0.0.0"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=env)
    try:
        served = dict(proc.stdout.readline().split()[::2] for _ in cfg["devices"])
        resource = served["pm100"]
        assert resource.startswith("TCPIP0::0.0.0.0::") and resource.endswith("::SOCKET")
        with socket.create_connection(("127.0.0.1", int(resource.split("::")[2]))) as meter:
            meter.sendall(b"*IDN?\n")
            assert meter.makefile("rb").readline().startswith(b"Thorlabs,PM100")
    finally:
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=20)
    assert proc.returncode == 0, err
    assert err.strip() == ("gonio emulate: warning: --bind 0.0.0.0: pm100 listen beyond this "
                           "machine: anyone who can reach it can move the stages and read the "
                           "detector")
