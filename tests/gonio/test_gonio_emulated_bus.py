"""`gonio emulate` serves a Modbus RTU bus at the config's baud rate, which sets the silence
(t3.5) that ends an RTU frame on the emulated line."""

from pathlib import Path

import pytest

from gonio.config import load_config
from gonio.simulate import serve
from sim.devices.modbus_server import rtu_silent_interval_s

EXAMPLES = Path(__file__).resolve().parents[2] / "examples" / "instruments"


@pytest.mark.parametrize("baudrate", [9600, 115200])
def test_rtu_bus_uses_the_configured_baud_rate(tmp_path, baudrate):
    text = (EXAMPLES / "sim-modbus.toml").read_text()
    assert "baudrate = 115200" in text
    config = tmp_path / "instrument.toml"
    config.write_text(text.replace("baudrate = 115200", f"baudrate = {baudrate}").replace(
        "../registermaps/", f"{EXAMPLES.parent / 'registermaps'}/"))
    bench = serve(load_config(config))
    try:
        server = bench.emulators["photodiode"]
        assert server.baudrate == baudrate
        assert rtu_silent_interval_s(server.baudrate) == pytest.approx(
            3.5 * 11 / 9600 if baudrate == 9600 else 1.75e-3)
    finally:
        bench.stop()
