"""Fuzzed bad plans and configs through `gonio scan`: one clear error line each, no traceback,
and no motion — the config's ports do not exist, so any attempt to open a device would show
as a "cannot open" error; an invalid input must be refused before that, with no run
directory made."""

import contextlib
import io
import json
import tempfile
import tomllib
from pathlib import Path

import pytest
from gonio_testkit import EXAMPLES, dump_toml, fast_config, one_line_error
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from gonio_cli.main import main

PLAN = tomllib.loads((EXAMPLES / "plans" / "demo.toml").read_text())
PLAN.pop("instrument")
PLAN["grid"][0]["phi_o_deg"] = [0.0]
PLAN["point"] = [{"side": "transmission", "theta_i_deg": 10.0, "theta_o_deg": 5.0}]


def offline_config(name):
    cfg = fast_config(name)
    for i, dev in enumerate(cfg["devices"].values()):
        dev.update({"port": f"/nonexistent/tty{i}"} if "port" in dev else
                   {"host": "127.0.0.1", "tcp_port": 9})  # discard port: nothing listens
    return cfg


CONFIGS = {name: offline_config(name) for name in ("sim-serial", "sim-modbus")}

junk = st.one_of(
    st.text(alphabet=st.characters(min_codepoint=32, max_codepoint=126), max_size=6),
    st.integers(-10**20, 10**20), st.floats(allow_nan=True, allow_infinity=True),
    st.booleans(), st.lists(st.one_of(st.integers(-5, 400), st.text(max_size=2)), max_size=3),
    st.dictionaries(st.sampled_from(["start", "stop", "step", "num", "x"]),
                    st.integers(-400, 400), max_size=3))


def paths(data, prefix=()):
    """Every (key path) inside nested dicts and lists of a TOML document."""
    items = data.items() if isinstance(data, dict) else enumerate(data)
    for key, value in items:
        yield (*prefix, key)
        if isinstance(value, (dict, list)):
            yield from paths(value, (*prefix, key))


def mutate(data, path, action, value):
    """A deep copy of data with the value at path replaced, deleted, or joined by a stray key."""
    data = tomllib.loads(dump_toml(data))
    *parents, last = path
    node = data
    for key in parents:
        node = node[key]
    if action == "replace":
        node[last] = value
    elif action == "delete" and isinstance(node, dict):
        del node[last]
    elif isinstance(node, dict):
        node[f"{last}_typo"] = value
    else:
        node[last] = value
    return data


def scan(plan_text, cfg_text, *extra):
    """Run `gonio scan` in-process on the texts; (exit code, stderr, status of runs made)."""
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        (tmp / "plan.toml").write_text(plan_text)
        (tmp / "cfg.toml").write_text(cfg_text)
        err = io.StringIO()
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            code = main(["scan", str(tmp / "plan.toml"), "--instrument", str(tmp / "cfg.toml"),
                         "--out", str(tmp / "runs"), "--no-plot", "--no-progress", *extra])
        metas = [json.loads((run / "meta.json").read_text()) for run in (tmp / "runs").glob("*")
                 ] if (tmp / "runs").exists() else []
        runs = [f"{m['status']}: {m['reason'].split(':')[0]}" for m in metas]
        return code, err.getvalue(), runs


def opened_devices(line: str) -> bool:
    """True if the error came from opening a device (the serial port or the TCP host)."""
    return any(s in line for s in ("cannot open", "could not be opened",
                                   "connection to 127.0.0.1:9 failed"))


def check_plan(plan_text, cfg_text) -> int:
    """Exit code of `gonio plan` (validation only) on the texts."""
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        (tmp / "plan.toml").write_text(plan_text)
        (tmp / "cfg.toml").write_text(cfg_text)
        with contextlib.redirect_stderr(io.StringIO()), contextlib.redirect_stdout(io.StringIO()):
            return main(["plan", str(tmp / "plan.toml"), "--instrument", str(tmp / "cfg.toml")])


def check_refused_before_motion(plan, cfg):
    try:
        plan_text, cfg_text = dump_toml(plan), dump_toml(cfg)
        tomllib.loads(plan_text), tomllib.loads(cfg_text)
    except (TypeError, ValueError):
        assume(False)  # not expressible in TOML
    code, err, runs = scan(plan_text, cfg_text)
    assert code == 2, err
    line = one_line_error(err)
    assert runs == [], line  # no run directory: refused before (or when) opening devices
    if opened_devices(line):  # the mutation left a valid input: check it is one
        assert check_plan(plan_text, cfg_text) == 0


FUZZ = settings(max_examples=80, deadline=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])


@pytest.mark.slow
@FUZZ
@given(data=st.data(), action=st.sampled_from(["replace", "delete", "stray"]), value=junk)
def test_fuzzed_plans(data, action, value):
    path = data.draw(st.sampled_from(list(paths(PLAN))))
    check_refused_before_motion(mutate(PLAN, path, action, value), CONFIGS["sim-serial"])


@FUZZ
@pytest.mark.parametrize("name", sorted(CONFIGS))
@given(data=st.data(), action=st.sampled_from(["replace", "delete", "stray"]), value=junk)
def test_fuzzed_configs(name, data, action, value):
    cfg = CONFIGS[name]
    path = data.draw(st.sampled_from([p for p in paths(cfg) if p[0] != "sim"]))
    check_refused_before_motion({**PLAN, "grid": PLAN["grid"][:1]},
                                mutate(cfg, path, action, value))


@pytest.mark.parametrize("text", ["", "name = ", "[[grid]\n", "\x00\x01", "grid = 3"])
def test_broken_plan_files(text):
    code, err, runs = scan(text, dump_toml(CONFIGS["sim-serial"]))
    assert code == 2 and runs == []
    one_line_error(err)


def test_valid_inputs_reach_the_devices():
    """The control: unmutated, the same inputs pass validation and fail only at the port."""
    code, err, runs = scan(dump_toml(PLAN), dump_toml(CONFIGS["sim-serial"]))
    assert code == 2 and opened_devices(one_line_error(err)) and runs == []


SIM_CONFIG = fast_config("sim-serial")
SIM_CONFIG["sim"]["faults"] = {"esp": {"latency_s": 0.0}}
SIM_PLAN = {"grid": [{"theta_i_deg": [10.0], "theta_o_deg": [20.0]}]}


@settings(max_examples=40, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
@given(data=st.data(), action=st.sampled_from(["replace", "delete", "stray"]), value=junk)
def test_fuzzed_sim_sections(data, action, value):
    """Bad [sim] tables under --sim: one clear error line before any run exists."""
    path = data.draw(st.sampled_from([p for p in paths(SIM_CONFIG) if p[0] == "sim"]))
    cfg = mutate(SIM_CONFIG, path, action, value)
    try:
        cfg_text = dump_toml(cfg)
        tomllib.loads(cfg_text)
    except (TypeError, ValueError):
        assume(False)
    code, err, runs = scan(dump_toml(SIM_PLAN), cfg_text, "--sim")
    if code == 0:  # the mutation left a valid [sim]: the scan ran and completed
        assert runs == ["completed: "]
    else:
        assert code == 2 and runs == []
        one_line_error(err)


@pytest.mark.parametrize("scale", [8e-244, 0.5, 0, -1, "fast", True, 81535644010803.0])
def test_slow_motion_or_nonsense_time_scale_is_refused(scale):
    """Slow motion would let a fuzzed time scale stretch a move beyond any timeout."""
    cfg = {**SIM_CONFIG, "sim": {**SIM_CONFIG["sim"], "time_scale": scale}}
    code, err, runs = scan(dump_toml(SIM_PLAN), dump_toml(cfg), "--sim")
    assert code == 2 and runs == []
    assert "[sim] time_scale: must be a number >= 1" in one_line_error(err)
