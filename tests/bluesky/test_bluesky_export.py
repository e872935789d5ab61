"""`gonio export RUN --format bluesky`: a run scanned on the emulated bench as event-model
documents (JSON lines, `["name", {doc}]`), each valid against event-model's schemas, one
event per stored reading with its fields, the same file every time; and the same plan run
under Bluesky's RunEngine measures the same rows in the same order."""

from __future__ import annotations

import json
import math
from datetime import datetime

import numpy as np
import pytest

pytest.importorskip("event_model", reason="the bluesky export needs event-model")

from bluesky_testkit import small_plan, validated  # noqa: E402

from gonio.runner import new_scan  # noqa: E402
from gonio.store import open_run  # noqa: E402
from gonio_cli.main import main  # noqa: E402


@pytest.fixture(scope="module")
def scanned(tmp_path_factory):
    folder = tmp_path_factory.mktemp("export")
    plan_path = small_plan(folder)
    result = new_scan(plan_path, sim=True, out=folder / "runs", progress=False)
    assert result.outcome.status == "completed"
    return plan_path, result.path


def exported(run_dir, out):
    assert main(["export", str(run_dir), "--format", "bluesky", "--out", str(out)]) == 0
    return [tuple(json.loads(line)) for line in out.read_text().splitlines()]


def test_the_export_is_valid_event_model_documents_one_event_a_reading(scanned, tmp_path):
    _, run_dir = scanned
    docs = validated(exported(run_dir, tmp_path / "run.jsonl"))
    names = [name for name, _ in docs]
    rows = open_run(run_dir).rows()
    assert names == ["start", "descriptor", *["event"] * len(rows), "stop"]
    start, descriptor, stop = docs[0][1], docs[1][1], docs[-1][1]
    assert start["plan_name"] == "bluesky-small" and start["gonio"]["run"] == run_dir.name
    assert descriptor["run_start"] == start["uid"] and descriptor["name"] == "primary"
    assert descriptor["data_keys"]["power_w"]["units"] == "W"
    assert stop["exit_status"] == "success" and stop["num_events"] == {"primary": len(rows)}
    for seq, ((_, event), row) in enumerate(zip(docs[2:-1], rows, strict=True), start=1):
        assert event["seq_num"] == seq and event["descriptor"] == descriptor["uid"]
        for key, value in event["data"].items():
            stored = row.get(key)
            if isinstance(stored, float) and math.isnan(stored):
                assert isinstance(value, float) and math.isnan(value), key
            elif stored is not None:
                assert value == stored, key
        assert event["data"]["t_s"] == row["t_s"]


def test_event_times_are_wall_times_within_the_session_on_a_virtual_clock(scanned, tmp_path):
    # an all-emulated run counts t_s on the bench's virtual clock (run time, faster than the
    # wall under --time-scale inf): its events are stamped within its session's wall span
    _, run_dir = scanned
    session = open_run(run_dir).meta["sessions"][0]
    assert session["clock"] == "virtual"
    docs = exported(run_dir, tmp_path / "run.jsonl")
    times = [doc["time"] for name, doc in docs if name == "event"]
    begin = datetime.fromisoformat(session["start_utc"]).timestamp()
    end = datetime.fromisoformat(session["stop_utc"]).timestamp()
    assert times == sorted(times) and begin <= times[0] and times[-1] <= end
    assert docs[-1][1]["time"] == end


def test_exporting_twice_gives_the_same_file(scanned, tmp_path):
    _, run_dir = scanned
    a, b = tmp_path / "a.jsonl", tmp_path / "b.jsonl"
    exported(run_dir, a)
    exported(run_dir, b)
    assert a.read_bytes() == b.read_bytes()


def test_the_runengine_measures_the_rows_gonio_scan_stored(scanned):
    pytest.importorskip("ophyd_async", reason="gonio.bluesky needs ophyd-async (the bluesky extra)")
    from bluesky import RunEngine

    from gonio.bluesky import devices, plan

    plan_path, run_dir = scanned
    rows = open_run(run_dir).rows()
    RE = RunEngine()
    docs: list = []
    RE.subscribe(lambda name, doc: docs.append((name, doc)))
    with devices(plan_path.parent / "plan-instrument.toml", sim=True) as d:
        RE(plan(plan_path, d))
    got = [doc["data"] for name, doc in validated(docs) if name == "event"]
    assert [(e["schedule-index"], e["schedule-kind"], e["schedule-side"]) for e in got] == \
        [(r["index"], r["kind"], r["side"]) for r in rows]
    np.testing.assert_allclose(
        [(e["sample"], e["arm"]) for e in got],
        [(r["sample_deg"], r["arm_deg"]) for r in rows], rtol=1e-6, atol=1e-3)
