"""`gonio watch` without a browser: following a run another writer appends to (the store's
own line checks, torn last lines, damage), status and ETA, the incremental reduction and its
"not yet reducible" state, model curves only for an all-emulated run, the HTTP server's
documents and refusals (path traversal, foreign Host, cross-site control), the control relay
against a socket speaking the channel's protocol, and the CLI."""

import http.client
import json
import os
import select
import shutil
import socket
import subprocess
import sys
import threading
from contextlib import contextmanager
from urllib.parse import urlsplit

import numpy as np
import pytest
from gonio_testkit import ROOT, gonio_cli, one_line_error
from watch_testkit import plan_file

from calibration.pipeline import reduce_run
from calibration.plot import x_range
from gonio.runner import new_scan
from gonio.store import READINGS, RunWriter, encode_line, open_run
from gonio_watch.follow import RunFollower
from gonio_watch.model import NO_MODEL, ModelCurves
from gonio_watch.reduction import LiveReduction, panels_of
from gonio_watch.server import jsonable
from gonio_watch.status import Live, combined_status, eta_s, status_of
from gonio_watch.viewer import serving


@pytest.fixture(scope="module")
def source(tmp_path_factory):
    """A completed all-emulated run (instant motion) whose readings the tests replay."""
    folder = tmp_path_factory.mktemp("source")
    result = new_scan(plan_file(folder), sim=True, out=folder / "runs", progress=False)
    assert result.outcome.status == "completed"
    return open_run(result.path)


def empty_copy(source, root, **meta):
    """A new run directory with the source's plan, config and meta, and no readings yet."""
    keep = {k: v for k, v in source.meta.items()
            if k in ("plan_name", "instrument_name", "planned", "estimate_s", "sim", "seeds",
                     "time_scale", "calibration", "t0_epoch", "optics", "sample")}
    return RunWriter.create(root, "copy", None, None, source.plan, source.config,
                            {**keep, **meta})


def test_follower_takes_each_complete_line_and_waits_for_a_torn_one(source, tmp_path):
    writer = empty_copy(source, tmp_path)
    writer.close()  # the lines below are written by hand, torn on purpose
    follower = RunFollower(open_run(writer.path))
    rows = source.rows()
    path = writer.path / READINGS
    lines = [encode_line(r, run_uid=writer.meta["run_uid"]) for r in rows[:3]]
    with open(path, "ab") as fh:
        fh.write(lines[0] + lines[1] + lines[2][:25])
    follower.poll()
    snap = follower.snapshot()
    assert [r["index"] for r in snap.rows] == [0, 1] and snap.torn and snap.damage is None
    with open(path, "ab") as fh:
        fh.write(lines[2][25:])
    follower.poll()
    snap = follower.snapshot()
    assert snap.rows == rows[:3] and not snap.torn
    follower.poll()  # nothing new: the same rows, not read twice
    assert len(follower.snapshot().rows) == 3


def test_follower_reports_damage_as_the_store_does(source, tmp_path):
    writer = empty_copy(source, tmp_path)
    writer.close()
    line = bytearray(encode_line(source.rows()[0], run_uid=writer.meta["run_uid"]))
    at = line.index(b'"index": ') + len(b'"index": ')
    line[at:at + 1] = b"7"  # another index: still JSON, its checksum no longer matches
    (writer.path / READINGS).write_bytes(bytes(line))
    follower = RunFollower(open_run(writer.path))
    follower.poll()
    damage = follower.snapshot().damage
    assert "line 1: crc32 checksum mismatch (index 7)" in damage and "gonio check" in damage


def test_follower_starts_again_when_the_file_is_replaced(source, tmp_path):
    writer = empty_copy(source, tmp_path)
    for r in source.rows()[:4]:
        writer.append(r)
    writer.close()
    follower = RunFollower(open_run(writer.path))
    follower.poll()
    assert len(follower.snapshot().rows) == 4
    tmp = writer.path / "replacement"
    tmp.write_bytes(b"".join(encode_line(r, run_uid=writer.meta["run_uid"])
                             for r in source.rows()[:2]))
    os.replace(tmp, writer.path / READINGS)  # as a repair's copy would be
    follower.poll()
    assert [r["index"] for r in follower.snapshot().rows] == [0, 1]


def test_status_counts_positions_elapsed_and_eta(source):
    rows = source.rows()
    held = {"reason": "beam below 50 %", "index": 9, "t_s": 3.5, "resumed_t_s": None}
    # read as a real bench's run: its t_s on the wall clock (the source run's are virtual)
    wall = {k: v for k, v in source.meta["sessions"][0].items() if not k.startswith("clock")}
    meta = {**source.meta, "status": "running", "suspensions": [held], "sessions": [
        {**wall, "stop_utc": None}]}
    start = meta["sessions"][0]["start_utc"]
    from datetime import datetime
    now = datetime.fromisoformat(start).timestamp() + 12.5
    live = Live(True, {"ok": True, "state": "paused", "readings": 10, "planned": 99})
    out = status_of(source, meta, rows[:10], live, now)
    assert out["status"] == "paused" and out["readings"] == 10
    assert out["planned"] == source.meta["planned"] == len(rows)
    assert out["positions"] == {"sample": rows[9]["sample_deg"], "arm": rows[9]["arm_deg"]}
    assert out["elapsed_s"] == pytest.approx(12.5, abs=0.01)
    steps = np.diff([r["t_s"] for r in rows[:10]])
    assert out["eta_s"] == pytest.approx((len(rows) - 10) * np.median(steps))
    assert out["control"]["enabled"] and out["suspensions"] == [held]
    assert eta_s(meta, [], 20) == (meta["estimate_s"], "the plan's estimate")
    assert eta_s(meta, rows, len(rows)) == (0.0, "all readings stored")


@pytest.mark.parametrize("meta_status, live, expected", [
    ("running", Live(True, {"ok": True, "state": "pausing"}), "pausing"),
    ("running", Live(True, None, "no token"), "running"),
    ("running", Live(False, None, "no socket"), "not running"),
    ("paused", Live(True, {"ok": False, "error": "bad token"}), "paused"),
    ("completed", Live(False), "completed"),
    ("aborted", Live(False), "aborted"),
])
def test_combined_status(meta_status, live, expected):
    assert combined_status(meta_status, live) == expected


def test_reduction_waits_for_dark_and_beam_then_sends_only_what_changed(source):
    rows = source.rows()
    kinds = [r["kind"] for r in rows]
    t = [0.0]
    live = LiveReduction(source, clock=lambda: t[0])

    def reduce(n):
        t[0] += 10.0
        live.update(rows[:n])
        return live.since(version)

    version = 0
    first_beam = kinds.index("beam")
    out = reduce(first_beam)  # one dark reading, no beam: not yet
    assert out["state"] == "not yet reducible" and out["points"] == []
    assert "two dark readings" in out["reason"]
    n1 = [k for k, kind in enumerate(kinds) if kind == "beam"][1] + 1  # two of each
    out = reduce(n1)
    assert out["state"] == "reduced" and out["version"] == 1
    have = {p["i"] for p in out["points"]}
    assert have == {r["index"] for r in rows[:n1] if r["kind"] == "sample"}
    version = out["version"]
    n2 = n1 + [kind != "sample" for kind in kinds[n1:]].index(True)  # then samples only
    assert n2 > n1 + 2
    out = reduce(n2)
    assert {p["i"] for p in out["points"]} == {r["index"] for r in rows[n1:n2]}
    assert out["version"] == version + 1 and not out["replace"]
    version = out["version"]
    more = n2
    out = reduce(more)  # no new reading: nothing reduced, nothing sent
    assert out["points"] == [] and out["version"] == version
    out = reduce(len(rows))  # new beam readings renormalise every point
    assert len(out["points"]) == sum(k == "sample" for k in kinds)
    full = reduce_run(source.path)
    by_index = {p["i"]: p for p in live.since(0)["points"]}
    assert [by_index[i]["f"] for i in full.meta["index"]] == full.bsdf.tolist()
    panels = {p["key"]: p["points"] for p in out["panels"]}
    assert panels == {"0|reflection": 8, "30|reflection": 7, "0|transmission": 5}


def test_a_panel_spans_its_planned_angles_until_its_points_are_in():
    points = {i: {"key": "30|reflection", "x": x, "f": 1.0 + i, "valid": True}
              for i, x in enumerate((-70.0, -50.0))}
    wide = {"30|reflection": np.array([-70.0, -50.0, -30.0, 10.0, 50.0])}
    (panel,) = panels_of(points, wide)
    assert panel["x"] == [-90.0, 90.0] and panel["points"] == 2
    (panel,) = panels_of(points, {"30|reflection": np.array([-70.0, -50.0])})
    assert panel["x"] == list(x_range(np.array([-70.0, -50.0])))  # as gonio plot zooms
    assert panel["x"] != [-90.0, 90.0]


def test_reduction_replaces_what_no_longer_stands(source):
    rows = source.rows()
    t = [0.0]

    def flaky(run, readings):
        if len(readings) > 20:
            from calibration.values import CalibrationError
            raise CalibrationError("cannot reduce: a test's stand-in")
        return __import__("calibration.pipeline").pipeline.reduce_stored(run, readings)

    live = LiveReduction(source, reduce=flaky, clock=lambda: t[0])
    live.update(rows[:20])
    out = live.since(0)
    assert out["state"] == "reduced" and out["points"]
    t[0] += 10
    live.update(rows[:21])
    again = live.since(out["version"])
    assert again["state"] == "not yet reducible" and again["replace"] and again["points"] == []


def test_model_curves_only_for_an_all_emulated_run(source, tmp_path):
    t = [0.0]
    live = LiveReduction(source, clock=lambda: t[0])
    live.update(source.rows())
    out = ModelCurves().curves(live.reduced_meta(), ["0|transmission"])
    (curve, averaged) = out["curves"]["0|transmission"]
    assert curve["label"].startswith("emulator truth (ggx alpha 0.394")
    assert averaged["label"] == "emulator truth through the aperture"
    assert len(curve["x"]) == len(curve["y"]) and max(y or 0 for y in curve["y"]) > 1.0
    real = empty_copy(source, tmp_path, sim=False)
    for r in source.rows():
        real.append(r)
    real.close()
    run = open_run(real.path)
    live = LiveReduction(run, clock=lambda: t[0])
    live.update(run.rows())
    assert live.since(0)["state"] == "reduced"
    assert ModelCurves().curves(live.reduced_meta(), ["0|transmission"]) == {
        "note": NO_MODEL, "curves": {}}


def get(server, path, host=None, method="GET", body=None, headers=(), keyed=True):
    """(status, parsed JSON or bytes) of one request to the viewer, path sent as is; keyed:
    with the viewer's key in its cookie."""
    conn = http.client.HTTPConnection("127.0.0.1", server.port, timeout=10)
    conn.putrequest(method, path, skip_host=True)
    conn.putheader("Host", host or f"127.0.0.1:{server.port}")
    if keyed:
        conn.putheader("Cookie", f"{server.access.cookie_name}={server.access.key}")
    for name, value in headers:
        conn.putheader(name, value)
    if body is not None:
        conn.putheader("Content-Length", str(len(body)))
    conn.endheaders(body.encode() if body is not None else None)
    reply = conn.getresponse()
    data = reply.read()
    conn.close()
    is_json = reply.getheader("Content-Type", "").startswith("application/json")
    return reply.status, json.loads(data) if is_json else data


def test_server_serves_the_page_and_json_and_nothing_else(source):
    with serving(source.path) as server:
        status, page = get(server, "/")
        assert status == 200 and b'id="readings"' in page
        for asset in ("/watch.js", "/plot.js", "/watch.css"):
            assert get(server, asset)[0] == 200
        status, doc = get(server, "/status.json")
        assert status == 200 and doc["readings"] == doc["planned"] == len(source.rows())
        assert doc["status"] == "completed" and not doc["control"]["enabled"]
        assert "--token" in doc["control"]["why"]
        status, doc = get(server, "/data.json?since=5")
        assert doc["since"] == 5 and [p["i"] for p in doc["raw"]] == list(range(5, doc["readings"]))
        version = doc["reduced"]["version"]
        status, doc = get(server, f"/data.json?since={doc['readings']}&version={version}")
        assert doc["raw"] == [] and doc["reduced"]["points"] == []
        assert get(server, "/data.json?since=x")[0] == 400
        for path in ("/../meta.json", "/%2e%2e/meta.json", "/assets/../server.py",
                     "/..%2f..%2fmeta.json", "/readings.jsonl", "/meta.json",
                     "//etc/passwd", "/watch.js/../../meta.json", "/gonio_watch/server.py"):
            assert get(server, path)[0] == 404, path
        assert get(server, "/status.json", host="evil.example:80")[0] == 421
        assert get(server, "/status.json", host=f"evil.example:{server.port}")[0] == 421
        assert get(server, "/status.json", host=f"localhost:{server.port}")[0] == 200
        json_post = (("Content-Type", "application/json"),)
        status, doc = get(server, "/control/pause", method="POST", body="{}", headers=json_post)
        assert status == 403 and "--token" in doc["error"]
        status, doc = get(server, "/control/pause", method="POST", body="paused=1",
                          headers=(("Content-Type", "application/x-www-form-urlencoded"),))
        assert status == 415
        status, doc = get(server, "/control/pause", method="POST", body="{}",
                          headers=(*json_post, ("Origin", "http://evil.example")))
        assert status == 403 and "this page" in doc["error"]
        assert get(server, "/control/explode", method="POST", body="{}",
                   headers=json_post)[0] == 404
        assert get(server, "/control/pause", method="POST", body="{}" + " " * 5000,
                   headers=json_post)[0] == 413


def test_json_documents_hold_no_infinity_nor_nan():
    doc = {"p": float("inf"), "raw": [{"p": -float("inf")}, (1.5, float("nan"))], "n": 3}
    assert jsonable(doc) == {"p": None, "raw": [{"p": None}, [1.5, None]], "n": 3}


@contextmanager
def control_socket(run_dir, token):
    """A socket at RUN/control.sock speaking the control channel's protocol
    (docs: one JSON line each way), keeping a state the commands change."""
    state = {"state": "running"}
    path = run_dir / "control.sock"
    listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    listener.bind(str(path))
    listener.listen(4)
    seen = []

    def answer(request):
        seen.append(request.get("command"))
        if request.get("token") != token:
            return {"ok": False, "error": "bad token"}
        state["state"] = {"pause": "paused", "resume": "running",
                          "abort": "aborted"}.get(request["command"], state["state"])
        return {"ok": True, "state": state["state"], "readings": 7, "planned": 9}

    def serve():
        while True:
            try:
                conn, _ = listener.accept()
            except OSError:
                return
            with conn, conn.makefile("rb") as lines:
                for line in lines:
                    conn.sendall(json.dumps(answer(json.loads(line))).encode() + b"\n")

    threading.Thread(target=serve, daemon=True).start()
    try:
        yield seen
    finally:
        listener.shutdown(socket.SHUT_RDWR)
        listener.close()
        path.unlink()


def test_control_is_relayed_with_the_token(source, tmp_path):
    writer = empty_copy(source, tmp_path)
    writer.start_session()
    for r in source.rows()[:7]:
        writer.append(r)
    writer.wait_stored()
    json_only = (("Content-Type", "application/json"),)
    with control_socket(writer.path, "t0ken") as seen, \
            serving(writer.path, token="t0ken") as server:
        origin = (*json_only, ("Origin", f"http://127.0.0.1:{server.port}"))
        doc = get(server, "/status.json")[1]
        assert doc["status"] == "running" and doc["control"]["enabled"]
        assert doc["live"] == {"ok": True, "state": "running", "readings": 7, "planned": 9}
        status, reply = get(server, "/control/pause", method="POST", body="{}", headers=origin)
        assert status == 200 and reply["state"] == "paused"
        assert get(server, "/status.json")[1]["status"] == "paused"
        assert get(server, "/control/abort", method="POST", body="{}",
                   headers=json_only)[1]["state"] == "aborted"
        assert seen == ["status", "pause", "status", "abort"]
    with control_socket(writer.path, "other") as seen, \
            serving(writer.path, token="t0ken") as server:
        doc = get(server, "/status.json")[1]
        assert doc["status"] == "running" and not doc["control"]["enabled"]
        assert doc["control"]["why"] == "the scan refuses: bad token"
    with serving(writer.path, token="t0ken") as server:  # no socket: the scan is gone
        assert get(server, "/status.json")[1]["status"] == "not running"
        status, reply = get(server, "/control/resume", method="POST", body="{}",
                            headers=json_only)
        assert status == 503 and "not running" in reply["error"]
    writer.close()


def test_cli_prints_the_url_warns_on_a_wide_bind_and_ends_with_stdin(source):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, "-m", "gonio_cli", "watch", str(source.path),
                             "--token", "-", "--until-eof", "--bind", "0.0.0.0"],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env)
    proc.stdin.write("abc\n")
    proc.stdin.flush()
    url = proc.stdout.readline().strip()
    assert url.startswith("http://0.0.0.0:")
    conn = http.client.HTTPConnection("127.0.0.1", urlsplit(url).port)
    conn.request("GET", f"/status.json?{urlsplit(url).query}")
    assert json.loads(conn.getresponse().read())["readings"] == len(source.rows())
    proc.stdin.close()
    assert proc.wait(timeout=20) == 0
    err = proc.stderr.read()
    assert "warning: --bind 0.0.0.0" in err and "pause and abort" in err
    assert "abc" not in err  # the token is nowhere in the output
    fails = gonio_cli("watch", source.path / "nothing-here")
    assert fails.returncode == 2 and "not a run directory" in one_line_error(fails.stderr)


@pytest.mark.parametrize("kind", ["directory", "fifo"])
def test_a_readings_file_replaced_by_a_folder_or_fifo_is_one_warning(source, tmp_path, kind):
    """The attack: readings.jsonl of a watched run replaced by a folder (the follower's
    thread died with a traceback) or a FIFO (it hung holding its lock, and every request
    with it). One warning line, and the server still answers."""
    copy = tmp_path / "copy"
    shutil.copytree(source.path, copy)
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, "-m", "gonio_cli", "watch", str(copy),
                             "--until-eof"], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env)
    try:
        url = urlsplit(proc.stdout.readline().strip())
        (copy / READINGS).rename(copy / "moved.jsonl")
        os.mkdir(copy / READINGS) if kind == "directory" else os.mkfifo(copy / READINGS)
        readable, _, _ = select.select([proc.stderr], [], [], 60)  # a hang guard only
        assert readable, "no line on stderr: the follower hangs"
        warning = proc.stderr.readline()
        conn = http.client.HTTPConnection("127.0.0.1", url.port, timeout=30)
        conn.request("GET", f"/status.json?{url.query}")
        reply = conn.getresponse()
        assert reply.status == 200 and json.loads(reply.read())["readings"] == len(source.rows())
        proc.stdin.close()
        assert proc.wait(timeout=60) == 0
        rest = proc.stderr.read()
    finally:
        proc.kill()
    what = "a directory" if kind == "directory" else "a FIFO"
    assert warning == (f"gonio watch: warning: the live view cannot read the run: "
                       f"{copy / READINGS} is {what}, not a regular file\n"), warning + rest
    assert rest == ""


def test_scan_watch_serves_the_run_beside_the_scan(tmp_path):
    plan = plan_file(tmp_path, 15.0)  # readings for ~6 s
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, "-m", "gonio_cli", "scan", str(plan), "--sim",
                             "--out", str(tmp_path / "runs"), "--no-plot", "--no-progress",
                             "--watch"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=env)
    url = None
    for line in proc.stderr:
        if line.startswith("gonio scan: watch "):
            url = line.split()[-1]
            break
    assert url and url.startswith("http://127.0.0.1:")
    port, keyed = urlsplit(url).port, f"/status.json?{urlsplit(url).query}"

    def status() -> dict:
        conn = http.client.HTTPConnection("127.0.0.1", port, timeout=60)
        try:
            conn.request("GET", keyed)
            return json.loads(conn.getresponse().read())
        finally:
            conn.close()

    first = status()
    assert first["readings"] < first["planned"]
    seen: list[str] = []

    def page() -> None:  # asks as an open page does, until the viewer has gone
        try:
            while not threading.Event().wait(0.05):
                seen.append(status()["status"])
        except OSError:
            pass

    asking = threading.Thread(target=page, daemon=True)
    asking.start()
    rest = []  # stderr stays open while the viewer, which shares it, lingers
    threading.Thread(target=lambda: rest.extend(proc.stderr), daemon=True).start()
    out = proc.stdout.read()
    assert proc.wait(timeout=120) == 0, rest
    run = open_run(out.strip().splitlines()[-1])
    assert run.meta["status"] == "completed" and first["run"] == run.path.name
    assert first["planned"] == run.meta["planned"] == len(run.rows())
    # the viewer saw the page ask, so it lingered until the page was told the end
    asking.join(timeout=120)
    assert not asking.is_alive() and seen[-1] == "completed", seen[-5:]
