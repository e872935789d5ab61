"""Ports held, not shared: a second `gonio scan` on the ports a running scan holds is one
`in use` line naming the port and the first scan's process, exit 2, before it sends anything
and with no run directory; the first scan, mid-move and polling its ESP the whole time,
completes with no reading flagged `retried`.

The emulators run in this process (`gonio emulate`'s own serve), their stages on the bench's
virtual clock at real time and the arm at a crawl, so the first scan's first move cannot end
before the test moves the clock on: the overlap is certain, whatever the machine's load.
"""

import subprocess

from gonio_testkit import (
    fast_config,
    gonio_cli,
    one_line_error,
    pointed,
    run_dir_of,
    serving,
    start_gonio,
    write_plan,
    write_toml,
)
from waiting import wait_until

from gonio.reading_flags import RETRIED
from gonio.store import open_run

PLAN = {"name": "held", "grid": [{"theta_i_deg": [0.0], "theta_o_deg": [10.0, 20.0]}]}
CRAWL_DEG_S = 0.001  # the arm's speed: a degree takes 1000 s of the emulated clock
MOTION_COMMANDS = ("PA", "VA", "AC", "MO", "SL", "SR")  # what opening or moving sends the ESP


def test_a_second_scan_on_held_ports_is_refused_and_the_first_completes_unretried(tmp_path):
    cfg = fast_config(time_scale=1.0)
    cfg["axes"]["arm"]["speed_deg_s"] = CRAWL_DEG_S
    with serving(write_toml(tmp_path / "emulated.toml", cfg)) as (endpoints, bench):
        plan = write_plan(tmp_path, PLAN, pointed(cfg, endpoints))
        esp = bench.emulators["esp"]
        arm = esp.axes[2].motion
        first = start_gonio("scan", plan, "--out", tmp_path / "first", "--no-plot",
                            "--no-progress")
        wait_until(lambda: arm.is_moving() or first.poll() is not None,
                   what="the first scan's first move")
        sent = {command: esp.received[command] for command in MOTION_COMMANDS}
        second = gonio_cli("scan", plan, "--out", tmp_path / "second", "--no-plot",
                           "--no-progress")
        assert arm.is_moving() and first.poll() is None  # the first scan ran throughout
        assert {command: esp.received[command] for command in MOTION_COMMANDS} == sent
        wait_until(lambda: bench.clock.advance(3600.0) and first.poll() is not None,
                   what="the first scan's end, the emulated clock moved on")
        out, err = first.communicate(timeout=60)
    assert second.returncode == 2, second.stderr
    line = one_line_error(second.stderr)
    assert f"esp: {endpoints['esp'][1]} is in use by process {first.pid} (" in line
    assert not (tmp_path / "second").exists()  # refused before any run directory
    assert first.returncode == 0, err
    run = open_run(run_dir_of(subprocess.CompletedProcess([], 0, out, err)))
    rows = run.rows()
    assert len(rows) == run.meta["planned"] == 2
    assert [row["flags"] for row in rows if RETRIED in row["flags"].split(",")] == []
