"""The emulated Zaber product as [sim.devices.zaber] says it is (`device_id`, `firmware`, and
`alerts`, the comm.alert it saved), and `gonio scan --sim` on a copy of
examples/instruments/sim-zaber.toml whose stages send alerts: the run completes, no reading is
retried and the Zaber line needed no resync (the session's record of its line), with the
identity the product reported recorded; a bad [sim.devices.zaber] value is one error line."""

import pytest
from gonio_testkit import completed_unretried, gonio_cli, load_example, one_line_error, write_plan

from sim.devices.photodiode import SimConfigError
from sim.emulate import start

PLAN = {"name": "alerts", "averaging": 2, "dark": {"every": 4}, "beam": {"every": 4}, "grid": [
    {"side": "reflection", "theta_i_deg": [20.0, 40.0],
     "theta_o_deg": [-50.0, -10.0, 15.0, 35.0, 60.0]}]}
PRODUCT = {"device_id": 50419, "firmware": "7.33", "alerts": True}


def alerting_config(**product) -> dict:
    """The example as shipped (its time scale: alerts go out as motions end, in real time),
    the emulated product as `product` says, one node of the aperture quadrature."""
    cfg = load_example("sim-zaber")
    cfg["sim"]["devices"] = {"zaber": product}
    cfg["sim"].setdefault("aperture", {})["order"] = [0, 0]
    return cfg


def test_the_product_is_what_the_config_says():
    with start(alerting_config(**PRODUCT), devices=["zaber"]) as bench:
        device = bench.emulators["zaber"].devices[1]
        assert (device.get("deviceid"), device.get("version"), device.get("comm.alert")) == \
            ("50419", "7.33", "1")
    with start(alerting_config(), devices=["zaber"]) as bench:  # the defaults
        device = bench.emulators["zaber"].devices[1]
        assert (device.get("deviceid"), device.get("version"), device.get("comm.alert")) == \
            ("50001", "7.38", "0")


def test_a_scan_with_alerts_on_is_never_retried_nor_resynced(tmp_path):
    cfg = alerting_config(**PRODUCT)
    for device in ("zaber", "pm100"):  # a reply late under a loaded machine's real time is a
        cfg["devices"][device]["timeout_s"] = 30.0  # resync too: only an alert's would count
    plan = write_plan(tmp_path, PLAN, cfg)
    proc = gonio_cli("scan", plan, "--sim", "--out", tmp_path / "runs", "--no-plot",
                     "--no-progress")
    run = completed_unretried(proc)
    session = run.meta["sessions"][0]
    # how many alerts came where a reply was due depends on real-time races (a few, most
    # runs); none of them may cost a resync
    assert session["lines"]["zaber"]["resyncs"] == 0
    assert session["lines"]["pm100"] == {"resyncs": 0, "unsolicited": 0}
    identity = session["devices"]["zaber"]["identity"]
    assert (identity["device_id"], identity["firmware"]) == ("50419", "7.33")


@pytest.mark.parametrize("key, value, message", [
    ("device_id", "X-RSW60A", "device_id: must be a positive integer (the product's Zaber "
                              "device id), got 'X-RSW60A'"),
    ("firmware", 7.38, 'firmware: must be a firmware-7 version such as "7.38" (the protocol '
                       "emulated), got 7.38"),
    ("alerts", "on", "alerts: must be true or false (the comm.alert the device saved), got "
                     "'on'"),
    ("model", "X-RSW60A", "model: the zaber emulator takes no such key (keys: device_id, "
                          "firmware, alerts)"),
])
def test_a_bad_product_key_is_one_error_naming_it(key, value, message):
    with pytest.raises(SimConfigError) as err:
        start(alerting_config(**{key: value}))
    assert str(err.value) == f"[sim.devices.zaber] {message}"


def test_gonio_scan_refuses_it_in_one_line_and_makes_no_run(tmp_path):
    plan = write_plan(tmp_path, PLAN, alerting_config(alerts="yes"))
    proc = gonio_cli("scan", plan, "--sim", "--out", tmp_path / "runs", "--no-plot")
    assert proc.returncode == 2
    assert one_line_error(proc.stderr).endswith(
        "[sim.devices.zaber] alerts: must be true or false (the comm.alert the device saved), "
        "got 'yes'")
    assert not (tmp_path / "runs").exists() or not any((tmp_path / "runs").iterdir())
