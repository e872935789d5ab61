"""The run store: append-only readings, torn last lines, damaged lines refused everywhere,
resume without duplicates, repaired runs resumed."""

import errno
import json
import math
import os
import re
import shutil
import signal
import sys
import threading
import time
import zlib

import numpy as np
import pytest
from waiting import HANG_S, wait_until

import gonio.store
from gonio.errors import RunError
from gonio.integrity import check, repair
from gonio.plan.parse import POINT_DTYPE
from gonio.plan.schedule import SCHEDULE_DTYPE
from gonio.reading_flags import INVALID, RETRIED, flagged
from gonio.store import (
    READING_DTYPE,
    DamagedRunError,
    RunWriter,
    StoreError,
    digest_problems,
    open_run,
)

SLOW_FSYNC_S = 0.02  # how long the slow recorder's fsync of a line takes


def row(i, **kw):
    base = {name: 0.0 for name in READING_DTYPE.names}
    base.update(index=i, kind="sample", side="reflection", repeat=0, point=i, flags="",
                saturated=False, power_w=1e-6 * (i + 1), plan_theta_i_deg=math.nan)
    base.update(kw)
    return base


@pytest.fixture
def writer(tmp_path):
    w = RunWriter.create(tmp_path / "runs", "t", None, None, {"name": "t"}, {"name": "c"},
                         {"plan_name": "t"})
    w.start_session()
    yield w
    w.close()


def test_long_kind_side_and_flag_names_survive_the_store(writer):
    """Text fields have no fixed width: names far longer than today's come back whole."""
    long = {"kind": "signature-" + "k" * 60, "side": "transmission-" + "s" * 40,
            "flags": ",".join([RETRIED, INVALID, "f" * 80])}
    writer.append(row(0, **long))
    r = open_run(writer.path).readings()
    assert {name: r[name][0] for name in long} == long
    assert flagged(r, "f" * 80).tolist() == flagged(r, INVALID).tolist() == [True]


@pytest.mark.parametrize("dtype", [POINT_DTYPE, SCHEDULE_DTYPE, READING_DTYPE],
                         ids=["plan points", "schedule", "readings"])
def test_no_text_field_has_a_fixed_width(dtype):
    text = [name for name in dtype.names if dtype[name].kind in "OSU"]
    assert text  # source, side, kind, flags
    a = np.zeros(1, dtype)
    for name in text:
        a[name] = name * 50
        assert a[name][0] == name * 50, name


def test_append_and_read_back(writer):
    for i in range(5):
        writer.append(row(i))
    run = open_run(writer.path)
    r = run.readings()
    assert r.dtype == READING_DTYPE
    assert list(r["index"]) == list(range(5))
    np.testing.assert_allclose(r["power_w"], 1e-6 * np.arange(1, 6))
    assert np.isnan(r["plan_theta_i_deg"]).all()  # NaN is stored as JSON null
    assert "NaN" not in (writer.path / "readings.jsonl").read_text()
    assert run.plan == {"name": "t"} and run.config == {"name": "c"}
    assert run.meta["status"] == "running" and run.meta["versions"]["numpy"] == np.__version__


def test_infinite_power_survives(writer):
    writer.append(row(0, power_w=float("inf"), saturated=True))
    r = open_run(writer.path).readings()
    assert r["power_w"][0] == float("inf") and r["saturated"][0]


def test_a_line_is_the_rows_json_with_its_crc_last():
    """encode_line appends the crc to the row's text: the bytes json.dumps gives for the row
    with the crc as its last member, the crc over the canonical row (what check verifies)."""
    for r in (row(3), row(4, power_w=math.inf, flags="retried"), {}):
        line = gonio.store.encode_line(r)
        clean = {k: None if isinstance(v, float) and v != v else v for k, v in r.items()}
        crc = zlib.crc32(gonio.store.canonical_json(clean))
        assert line == json.dumps({**clean, "crc32": crc}).encode() + b"\n"
        assert gonio.store.encode_line(r, checksum=False) == json.dumps(clean).encode() + b"\n"


def test_out_of_order_append_is_refused(writer):
    writer.append(row(0))
    with pytest.raises(RunError, match="out of order"):
        writer.append(row(2))


@pytest.mark.parametrize("tail", [b'{"index": 3, "kind": "sam', b"\x00" * 300,
                                  b'{"index": 3, "ki' + b"\x00" * 40])
def test_torn_tail_is_ignored_and_cut_on_resume(writer, tail):
    """A torn last line: the bytes after the last newline (half a line, NUL padding)."""
    for i in range(3):
        writer.append(row(i))
    writer.close()
    with open(writer.path / "readings.jsonl", "ab") as fh:
        fh.write(tail)
    assert len(open_run(writer.path)) == 3
    resumed = RunWriter.resume(writer.path)
    assert resumed.next_index == 3
    resumed.append(row(3))
    resumed.close()
    r = open_run(writer.path).readings()
    assert list(r["index"]) == [0, 1, 2, 3]
    lines = (writer.path / "readings.jsonl").read_bytes().splitlines()
    assert [json.loads(x)["index"] for x in lines] == [0, 1, 2, 3]


def _crc_flipped(line: bytes) -> bytes:
    return line.replace(b'"power_w": ', b'"power_w": 9', 1)


DAMAGE = {  # how line 3 (index 2) of 6 is damaged -> what every reader says
    "garbage": (lambda lines: lines[:2] + [b"}{garbage"] + lines[3:], "line 3: not JSON"),
    "nul": (lambda lines: lines[:2] + [b"\x00" * 80] + lines[3:], "line 3: NUL bytes"),
    "duplicated": (lambda lines: lines[:2] + [lines[1]] + lines[2:],
                   "line 3: duplicate of index 1 (line 2)"),
    "crc": (lambda lines: lines[:2] + [_crc_flipped(lines[2])] + lines[3:],
            "line 3: crc32 checksum mismatch (index 2)"),
    "no crc": (lambda lines: lines[:2] + [re.sub(rb', "crc32": \d+', b"", lines[2])]
               + lines[3:], "line 3: no crc32 checksum (index 2)"),
    "swapped": (lambda lines: lines[:2] + [lines[3], lines[2]] + lines[4:],
                "line 3: index 3 follows index 1: index 2 missing (and 1 more damaged line)"),
    "deleted": (lambda lines: lines[:2] + lines[3:],
                "line 3: index 3 follows index 1: index 2 missing"),
    "last line": (lambda lines: lines[:5] + [b"{not json"], "line 6: not JSON"),
}


@pytest.mark.parametrize("kind", DAMAGE)
def test_a_damaged_line_is_an_error_for_every_reader_and_for_resume(writer, kind):
    damage, said = DAMAGE[kind]
    for i in range(6):
        writer.append(row(i))
    writer.close()
    path = writer.path / "readings.jsonl"
    path.write_bytes(b"\n".join(damage(path.read_bytes().splitlines())) + b"\n")
    run = open_run(writer.path)
    for read in (run.rows, run.readings, run.__len__):
        with pytest.raises(DamagedRunError, match=re.escape(f"readings.jsonl {said}")):
            read()
    before = path.read_bytes()
    with pytest.raises(DamagedRunError, match=r"cannot resume: `gonio check .* --repair "):
        RunWriter.resume(writer.path)
    assert path.read_bytes() == before  # nothing cut
    with pytest.raises(DamagedRunError):  # again, not "in use": the refusal freed the lock
        RunWriter.resume(writer.path)


def test_a_run_whose_meta_names_no_line_checksum_is_damaged(writer):
    """Deleting line_checksum from meta.json switches nothing off: the run is damaged for
    every reader and for resume; --force reads its lines as they are, naming the damage."""
    for i in range(3):
        writer.append(row(i))
    writer.close()
    path = writer.path / "readings.jsonl"
    edited = re.sub(rb', "crc32": \d+', b"", path.read_bytes(), count=1)  # line 1 unchecked
    path.write_bytes(edited.replace(b'"power_w": ', b'"power_w": 9', 1))
    meta = json.loads((writer.path / "meta.json").read_text())
    del meta["line_checksum"]
    (writer.path / "meta.json").write_text(json.dumps(meta))
    said = "meta.json names no line_checksum: the lines cannot be checked"
    with pytest.raises(DamagedRunError, match=said):
        open_run(writer.path).rows()
    with pytest.raises(DamagedRunError, match=said):
        RunWriter.resume(writer.path)
    assert check(open_run(writer.path)).damaged
    forced = open_run(writer.path, force=True)
    assert len(forced.rows()) == 3 and forced.read_past == [said]


def test_an_older_run_without_run_identity_reads_and_resumes(writer):
    """line_checksum crc32, the older scheme: lines carry no run uid, and are still read,
    resumed in their own format, and checked with a note saying what it cannot tell."""
    for i in range(3):
        writer.append(row(i))
    writer.close()
    old = [gonio.store.encode_line(r) for r in open_run(writer.path).rows()]
    (writer.path / "readings.jsonl").write_bytes(b"".join(old))
    meta = json.loads((writer.path / "meta.json").read_text())
    del meta["run_uid"]
    (writer.path / "meta.json").write_text(json.dumps({**meta, "line_checksum": "crc32"}))
    assert len(open_run(writer.path)) == 3
    resumed = RunWriter.resume(writer.path)
    resumed.append(row(3))
    resumed.close()
    lines = (writer.path / "readings.jsonl").read_bytes().splitlines()
    assert lines[3] == gonio.store.encode_line(row(3)).strip()
    report = check(open_run(writer.path))
    assert not report.damaged and len(report.lines.rows) == 4
    assert any("carry no run identity" in note for note in report.notes)


def test_a_repaired_run_measures_its_dropped_indices_first(writer, tmp_path):
    for i in range(5):
        writer.append(row(i))
    writer.close()
    path = writer.path / "readings.jsonl"
    lines = path.read_bytes().splitlines(keepends=True)
    path.write_bytes(b"".join(lines[:1] + [b"garbage\n"] + lines[2:3] + [b"\x00\n"] + lines[4:]))
    copy = repair(check(open_run(writer.path)), tmp_path / "copy")
    run = open_run(copy)
    assert run.meta["repair"]["dropped"] == [1, 3] and list(run.readings()["index"]) == [0, 2, 4]
    resumed = RunWriter.resume(copy)
    assert (resumed.todo(7), resumed.stored) == ([1, 3, 5, 6], 3)
    resumed.start_session()
    with pytest.raises(RunError, match="out of order"):
        resumed.append(row(5))
    for i in resumed.todo(7):
        resumed.append(row(i))
    resumed.set_status("completed", "")
    resumed.close()
    run = open_run(copy)
    assert list(run.readings()["index"]) == list(range(7))
    assert run.meta["sessions"][-1]["refill"] == [1, 3]
    report = check(run)
    assert not report.damaged, report.text()


def test_completed_run_cannot_be_resumed(writer):
    writer.append(row(0))
    writer.set_status("completed", "")
    with pytest.raises(RunError, match="already completed"):
        RunWriter.resume(writer.path)
    meta = open_run(writer.path).meta
    assert meta["sessions"][-1]["status"] == "completed" and meta["stopped_utc"]


def test_not_a_run_directory(tmp_path):
    with pytest.raises(RunError, match="not a run directory"):
        open_run(tmp_path)


def test_a_run_has_one_writer_at_a_time(writer):
    writer.append(row(0))
    with pytest.raises(RunError, match="in use by another gonio process"):
        RunWriter.resume(writer.path)
    writer.close()
    again = RunWriter.resume(writer.path)  # the lock went with the first writer
    assert again.next_index == 1
    again.close()


def _readings_fsyncs(monkeypatch, fail: bool = False, held: threading.Event | None = None
                     ) -> list[tuple[int, int]]:
    """Route the store's fsyncs of readings.jsonl through a slow recorder (file size when the
    fsync started and when it returned), one held until `held` is set, or, with fail, an I/O
    error; returns the records."""
    real_fsync, calls = os.fsync, []

    def fsync(fd: int) -> None:
        if not os.readlink(f"/proc/self/fd/{fd}").endswith("readings.jsonl"):
            return real_fsync(fd)
        if fail:
            raise OSError(errno.EIO, "Input/output error")
        started = os.fstat(fd).st_size
        if held is None:
            time.sleep(SLOW_FSYNC_S)  # a slow disk, the thing tested: the next line waits
        else:
            assert held.wait(HANG_S), "the test never let the fsync return"
        real_fsync(fd)
        calls.append((started, os.fstat(fd).st_size))

    monkeypatch.setattr(gonio.store.os, "fsync", fsync)
    return calls


def _main_thread_in(function: str) -> bool:
    """True while the main thread runs `function` (at any depth of its stack)."""
    frame = sys._current_frames().get(threading.main_thread().ident)
    while frame is not None and frame.f_code.co_name != function:
        frame = frame.f_back
    return frame is not None


def test_each_line_is_written_at_once_and_fsynced_before_the_next(writer, monkeypatch):
    """A line is in the file when append returns (a reader, or a kill right after, sees it);
    its fsync runs on while the engine goes on, the next line waits for it, and meta.json
    reports the run stopped only once the last one returned."""
    fsyncs = _readings_fsyncs(monkeypatch)
    for i in range(4):
        writer.append(row(i))
        assert len(open_run(writer.path)) == i + 1
    writer.set_status("paused", "")
    size = (writer.path / "readings.jsonl").stat().st_size
    assert len(fsyncs) == 4  # one per reading, the last one awaited by set_status
    assert all(start == end for start, end in fsyncs)  # nothing written during an fsync
    assert [end for _, end in fsyncs] == sorted({end for _, end in fsyncs})
    assert fsyncs[-1][1] == size
    assert open_run(writer.path).meta["sessions"][-1]["last_index"] == 3


def test_a_failed_fsync_stops_the_writing(writer, monkeypatch):
    _readings_fsyncs(monkeypatch, fail=True)
    writer.append(row(0))
    with pytest.raises(StoreError, match=r"readings.jsonl: Input/output error"):
        writer.append(row(1))
    assert len(open_run(writer.path)) == 1  # no line after the one the disk refused


def test_ctrl_c_while_waiting_for_an_fsync_leaves_it_awaited(writer, monkeypatch):
    """A second Ctrl-C (KeyboardInterrupt) that lands while append waits for the previous
    line's fsync: the run then stops, and meta.json must still come after that fsync."""
    held = threading.Event()
    fsyncs = _readings_fsyncs(monkeypatch, held=held)
    writer.append(row(0))

    def ctrl_c_in_the_wait() -> None:
        wait_until(lambda: _main_thread_in("wait_stored"), what="append waiting for the fsync")
        signal.pthread_kill(threading.main_thread().ident, signal.SIGINT)

    # Python's own Ctrl-C handler, whatever an import at collection left in this worker
    # (gonio_cli.main sets one of its own until main() runs)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        threading.Thread(target=ctrl_c_in_the_wait, daemon=True).start()
        with pytest.raises(KeyboardInterrupt):
            writer.append(row(1))
    finally:
        signal.signal(signal.SIGINT, previous)
    assert fsyncs == []  # interrupted before the fsync of line 0 returned
    held.set()
    writer.set_status("aborted", "aborted by the user (Ctrl-C)")
    assert len(fsyncs) == 1  # set_status waited for it
    assert len(open_run(writer.path)) == 1


def test_register_maps_count_by_content_not_path(tmp_path):
    """The digests of a run cover its register maps' contents: a moved copy of the same map
    passes, an edited one (or plan.json) does not."""
    regmap = tmp_path / "drive.toml"
    regmap.write_text("[registers]\n")
    config = {"name": "c", "devices": {"drive": {"register_map": str(regmap)}}}
    w = RunWriter.create(tmp_path / "runs", "t", None, None, {"name": "t"}, config, {})
    w.close()
    run = open_run(w.path)
    moved = tmp_path / "elsewhere.toml"
    shutil.copyfile(regmap, moved)
    assert digest_problems(run, {"devices": {"drive": {"register_map": str(moved)}}}) == []
    moved.write_text("[registers]\nvelocity = 1\n")
    assert digest_problems(run, {"devices": {"drive": {"register_map": str(moved)}}}) == [
        "the register map of device 'drive' differs in content from the one the run started with"]
    (w.path / "plan.json").write_text('{"name": "u"}')
    assert digest_problems(open_run(w.path)) == [
        "plan.json changed since the run started (its digest differs)"]
