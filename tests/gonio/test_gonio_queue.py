"""`gonio queue` in real processes: queued plans run one after another into complete runs; a
SIGKILL of `gonio queue run` mid-run is resumed by the next one (every reading once) while a
second runner is refused; SIGTERM aborts the entry and stops the queue; a failed run stops it
unless --keep-going; a bad plan is refused whole at add. Hand edits of queue.toml, even while
its queue runs, mark no unmeasured plan completed (entries are found by id; a run counts only
for the plan it measured); `queue list` names what it cannot read. Then queue.toml's own
checks, in process."""

import fcntl
import os
import signal
import subprocess
import sys
import tomllib

import pytest
from gonio_testkit import (
    ROOT,
    completed_unretried,
    fast_config,
    gonio_cli,
    one_line_error,
    start_gonio,
    wait_for_lines,
    write_toml,
)
from waiting import wait_until

from gonio.engine import PauseControl
from gonio.errors import QueueError
from gonio.queue import (
    Entry,
    identify,
    load,
    next_position,
    queue_path,
    render,
    run_entry,
)
from gonio.store import open_run

SHORT = {"name": "short", "grid": [{"side": "transmission", "theta_i_deg": [0.0],
                                    "theta_o_deg": [-20.0, 0.0, 20.0]}]}
# long enough that a runner stopped after its third reading has readings left to resume (with
# 7 readings all were stored before the stop landed once the scan got faster)
LONG = {"name": "long", "grid": [{"side": "reflection", "theta_i_deg": [10.0],
                                  "theta_o_deg": {"start": -60.0, "stop": 60.0, "step": 5.0},
                                  "skip_forbidden": True}]}


@pytest.fixture
def bench(tmp_path):
    """A fast emulated config and the two plans naming it; the queue's folder."""
    write_toml(tmp_path / "instrument.toml", fast_config(pm100={"timeout_s": 10.0}))
    for plan in (SHORT, LONG):
        write_toml(tmp_path / f"{plan['name']}.toml", {**plan, "instrument": "instrument.toml"})
    return tmp_path, tmp_path / "runs"


def queue(*args):
    return gonio_cli("queue", *args)


def entries(out) -> list[dict]:
    return tomllib.loads(queue_path(out).read_text())["entry"]


def assert_complete(run_dir, planned: int, sessions: int = 1) -> None:
    """A completed run: every index of its schedule once, in order."""
    run = open_run(run_dir)
    assert run.meta["status"] == "completed"
    assert run.meta["planned"] == planned
    assert list(run.readings()["index"]) == list(range(planned))
    assert len(run.meta["sessions"]) == sessions


def test_queued_plans_run_one_after_another_from_their_copies(bench):
    root, out = bench
    added = queue("add", root / "short.toml", root / "long.toml", "--sim", "--out", out)
    assert added.returncode == 0, added.stderr
    short_n, long_n = (int(ln.rsplit("/", 1)[1]) for ln in added.stdout.splitlines())
    assert [ln.split("  ")[:6] for ln in added.stdout.splitlines()] == [
        ["1", str(root / "short.toml"), str(root / "instrument.toml"), "sim", "pending", "-"],
        ["2", str(root / "long.toml"), str(root / "instrument.toml"), "sim", "pending", "-"]]
    write_toml(root / "short.toml", {**LONG, "name": "short"})  # queued: the copy runs
    proc = queue("run", "--out", out, "--no-plot", "--no-progress")
    assert proc.returncode == 0, proc.stderr
    recorded = entries(out)
    assert [e["state"] for e in recorded] == ["completed", "completed"]
    assert [str(out / e["run"]) for e in recorded] == proc.stdout.split()
    for entry, planned, name in zip(recorded, (short_n, long_n), ("short", "long"), strict=True):
        assert_complete(out / entry["run"], planned)
        assert open_run(out / entry["run"]).meta["plan_name"] == name
    listed = queue("list", "--out", out)
    assert listed.returncode == 0, listed.stderr
    assert [ln.split("  ")[4:] for ln in listed.stdout.splitlines()] == [
        ["completed", str(out / recorded[0]["run"]), f"{short_n}/{short_n}"],
        ["completed", str(out / recorded[1]["run"]), f"{long_n}/{long_n}"]]


def test_a_killed_queue_resumes_its_running_entry_and_refuses_a_second_runner(bench):
    root, out = bench
    added = queue("add", root / "long.toml", root / "short.toml", "--sim", "--out", out)
    assert added.returncode == 0, added.stderr
    long_n, short_n = (e["planned"] for e in entries(out))
    runner = start_gonio("queue", "run", "--out", out, "--no-plot", "--no-progress")
    try:
        wait_for_lines(out, 3, runner)
        runner.send_signal(signal.SIGSTOP)  # holds its lock, stores nothing more
        second = queue("run", "--out", out)
        assert second.returncode == 2
        assert f"being run by another `gonio queue run` (pid {runner.pid})" \
            in one_line_error(second.stderr)
        runner.send_signal(signal.SIGKILL)
    finally:
        runner.communicate(timeout=30)
    assert runner.returncode == -signal.SIGKILL, "the queue finished before it could be killed"
    first, rest = entries(out)
    assert (first["state"], rest["state"], rest["run"]) == ("running", "pending", "")
    stored = len(open_run(out / first["run"]).rows())
    assert 3 <= stored < long_n
    proc = queue("run", "--out", out, "--no-plot", "--no-progress")
    assert proc.returncode == 0, proc.stderr
    assert "resuming" in proc.stderr
    done = entries(out)
    assert [e["state"] for e in done] == ["completed", "completed"]
    assert done[0]["run"] == first["run"]
    assert_complete(out / first["run"], long_n, sessions=2)  # nothing lost or doubled
    assert_complete(out / done[1]["run"], short_n)
    assert sorted(p.name for p in out.iterdir()) == sorted(
        ["queue", "queue.toml", first["run"], done[1]["run"]])


def test_sigterm_aborts_the_entry_and_stops_the_queue(bench):
    root, out = bench
    assert queue("add", root / "long.toml", root / "short.toml", "--sim",
                 "--out", out).returncode == 0
    runner = start_gonio("queue", "run", "--out", out, "--no-plot", "--no-progress")
    wait_for_lines(out, 2, runner)
    runner.send_signal(signal.SIGTERM)
    stdout, stderr = runner.communicate(timeout=30)
    assert runner.returncode == 128 + signal.SIGTERM, stderr
    first, rest = entries(out)
    assert (first["state"], first["reason"]) == ("aborted", "SIGTERM")
    assert stdout.split() == [str(out / first["run"])]
    assert open_run(out / first["run"]).meta["status"] == "aborted"
    assert (rest["state"], rest["run"]) == ("pending", "")


def test_a_failed_run_stops_the_queue_unless_keep_going(bench):
    """Real devices on ports that do not exist: each entry fails as it opens them."""
    root, out = bench
    real = fast_config()
    for name, dev in real["devices"].items():
        dev["port"] = str(root / f"no-such-port-{name}")
    write_toml(root / "real.toml", real)
    assert queue("add", root / "short.toml", root / "long.toml", "--instrument",
                 root / "real.toml", "--out", out).returncode == 0
    stopped = queue("run", "--out", out, "--no-plot", "--no-progress")
    assert stopped.returncode == 2
    assert "no-such-port" in one_line_error(stopped.stderr.split("\n", 1)[1])
    assert [(e["state"], "no-such-port" in e["reason"], e["run"]) for e in entries(out)] == [
        ("failed", True, ""), ("pending", False, "")]
    going = queue("run", "--out", out, "--keep-going", "--no-plot", "--no-progress")
    assert going.returncode == 1, going.stderr
    assert going.stderr.count("failed: esp: serial port") == 2
    assert going.stderr.splitlines()[-1] == "gonio queue: 2 of 2 entries failed: 1, 2"
    assert [(e["state"], "no-such-port" in e["reason"]) for e in entries(out)] == [
        ("failed", True), ("failed", True)]
    assert not list(out.glob("*/readings.jsonl"))


def test_a_bad_plan_is_refused_and_nothing_is_added(bench):
    root, out = bench
    assert queue("add", root / "short.toml", "--sim", "--out", out).returncode == 0
    before = queue_path(out).read_bytes()
    bad = write_toml(root / "bad.toml", {  # valid alone; on this bench inside the beam
        "instrument": "instrument.toml",
        "grid": [{"side": "reflection", "theta_i_deg": [0.0], "theta_o_deg": [-20.0, 2.0]}]})
    proc = queue("add", root / "long.toml", bad, "--sim", "--out", out)
    assert proc.returncode == 2
    error = one_line_error(proc.stderr)
    assert str(bad) in error and "theta_o=2" in error and "beam clearance" in error
    assert queue_path(out).read_bytes() == before
    assert sorted(p.name for p in (out / "queue").iterdir() if p.is_dir()) == ["01"]


def test_a_damaged_queue_file_is_one_error_naming_the_entry_and_field(bench):
    root, out = bench
    assert queue("add", root / "short.toml", root / "long.toml", "--sim",
                 "--out", out).returncode == 0
    head, tail = queue_path(out).read_text().rsplit('state = "pending"', 1)
    queue_path(out).write_text(head + 'state = "done"' + tail)  # entry 2's
    proc = queue("run", "--out", out)
    assert proc.returncode == 2
    assert one_line_error(proc.stderr) == (
        f"gonio queue: error: {queue_path(out)}: [entry[2]] state: must be one of pending, "
        f"running, completed, failed, aborted; got 'done'")
    assert [e["state"] for e in entries(out)] == ["pending", "done"]  # nothing ran


def edit_by_hand(out, change) -> None:
    """Rewrite queue.toml's text as change(blocks) says (blocks: its [[entry]] tables' text,
    in order), holding the queue's state lock as `gonio queue add` would: never while the
    runner writes."""
    with (out / "queue" / "state.lock").open("a+") as lock:
        fcntl.flock(lock.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        head, *blocks = queue_path(out).read_text().split("\n[[entry]]\n")
        queue_path(out).write_text("\n[[entry]]\n".join([head, *change(blocks)]))


def run_dirs(out) -> set:
    return {p.name for p in out.iterdir() if (p / "meta.json").exists()}


def edited_while_running(root, out, change) -> tuple[str, int, int, str]:
    """Entry 1 (short) run; long and short queued after it; `gonio queue run` stopped
    (SIGSTOP) once entry 2 stored 3 readings, queue.toml edited by change, the runner let go
    to its end: (entry 1's run, long's and short's planned readings, the runner's stderr)."""
    assert queue("add", root / "short.toml", "--sim", "--out", out).returncode == 0
    assert queue("run", "--out", out, "--no-plot", "--no-progress").returncode == 0
    first_run = entries(out)[0]["run"]
    assert queue("add", root / "long.toml", root / "short.toml", "--sim",
                 "--out", out).returncode == 0
    long_n, short_n = (e["planned"] for e in entries(out)[1:])
    runner = start_gonio("queue", "run", "--out", out, "--no-plot", "--no-progress")
    try:
        def second_run_measuring():
            found = [out / name / "readings.jsonl" for name in run_dirs(out) - {first_run}]
            return runner.poll() is not None or any(
                p.read_bytes().count(b"\n") >= 3 for p in found)

        wait_until(second_run_measuring, 60, "the second entry's readings")
        runner.send_signal(signal.SIGSTOP)
        edit_by_hand(out, change)
        runner.send_signal(signal.SIGCONT)
        _, stderr = runner.communicate(timeout=120)
    finally:
        runner.kill()
    assert runner.returncode == 0, stderr
    return first_run, long_n, short_n, stderr


def test_deleting_a_finished_entry_while_the_queue_runs_completes_no_unmeasured_plan(bench):
    """The attack: entry 1 done, the queue running entry 2, entry 1 deleted from queue.toml.
    Entry 2 is recorded on itself, not on entry 3, which the queue then measures into a run
    of its own."""
    root, out = bench
    first_run, long_n, short_n, _ = edited_while_running(root, out, lambda b: b[1:])
    long_entry, short_entry = entries(out)
    assert (long_entry["state"], short_entry["state"]) == ("completed", "completed")
    assert len({first_run, long_entry["run"], short_entry["run"]}) == 3
    assert_complete(out / long_entry["run"], long_n)
    assert_complete(out / short_entry["run"], short_n)
    assert open_run(out / short_entry["run"]).meta["plan_name"] == "short"


def test_deleting_the_running_entry_records_its_outcome_nowhere_else(bench):
    """The running entry itself deleted: its run ends completed in its directory, one line
    says the queue recorded it nowhere, and the other entries are as they were, then run."""
    root, out = bench
    first_run, long_n, short_n, stderr = edited_while_running(
        root, out, lambda b: [b[0], *b[2:]])
    first, short_entry = entries(out)
    assert first["run"] == first_run and short_entry["state"] == "completed"
    (long_run,) = run_dirs(out) - {first_run, short_entry["run"]}
    assert_complete(out / long_run, long_n)
    assert_complete(out / short_entry["run"], short_n)
    told = [line for line in stderr.splitlines() if "while it ran" in line]
    assert len(told) == 1 and f"is recorded in {out / long_run} only" in told[0]


@pytest.mark.parametrize("other", ["another entry's run", "a run of another plan"])
def test_an_entry_pointed_at_another_run_is_not_completed(bench, other):
    """The attack: a pending entry's `run` set by hand to a completed run that is not its own
    (another entry's, of the same plan; or one `gonio scan` made of another plan). The queue
    refuses it (one error line naming why) and measures nothing; the run is untouched, and
    `queue list` says it is not the entry's."""
    root, out = bench
    if other == "another entry's run":
        assert queue("add", root / "short.toml", "--sim", "--out", out).returncode == 0
        assert queue("run", "--out", out, "--no-plot", "--no-progress").returncode == 0
        taken = entries(out)[0]["run"]
        second, reason = root / "short.toml", f"run {taken} is also the run of entry "
    else:
        made = gonio_cli("scan", root / "short.toml", "--sim", "--out", out, "--no-plot")
        taken = completed_unretried(made).path.name
        second = root / "long.toml"
        reason = f"run {taken} was not measured from the entry's plan"
    assert queue("add", second, "--sim", "--out", out).returncode == 0
    before = (out / taken / "readings.jsonl").read_bytes()
    edit_by_hand(out, lambda blocks: [*blocks[:-1], blocks[-1].replace(
        'run = ""', f'run = "{taken}"')])
    proc = queue("run", "--out", out, "--no-plot", "--no-progress")
    assert proc.returncode == 2
    assert reason in one_line_error(proc.stderr.split("\n", 1)[1])  # after "...: resuming"
    recorded = entries(out)[-1]
    assert recorded["state"] == "failed" and reason in recorded["reason"]
    assert run_dirs(out) == {taken}
    assert (out / taken / "readings.jsonl").read_bytes() == before
    listed = queue("list", "--out", out)
    assert listed.returncode == 1 and listed.stderr == ""
    assert f"  (not this entry's run: {reason}" in listed.stdout.splitlines()[-1]


def full_pipe() -> tuple[int, int]:
    """A pipe (read end, write end) whose buffer is full: the next write to it waits until
    the read end is read."""
    read_end, write_end = os.pipe()
    os.set_blocking(write_end, False)
    try:
        while True:
            os.write(write_end, b"\n" * 4096)
    except BlockingIOError:
        pass
    os.set_blocking(write_end, True)
    return read_end, write_end


def test_an_entry_added_by_hand_after_the_last_record_runs_once(bench):
    """The attack: an entry appended without an id between the runner's last record of an
    entry and its next reading of queue.toml (the runner held there by its run's path, which
    it prints on a full stdout). Its plan is measured once, and its outcome recorded."""
    root, out = bench
    assert queue("add", root / "short.toml", "--sim", "--out", out).returncode == 0
    read_end, write_end = full_pipe()
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    runner = subprocess.Popen([sys.executable, "-m", "gonio_cli", "queue", "run", "--out",
                               str(out), "--no-plot", "--no-progress"], stdin=subprocess.DEVNULL,
                              stdout=write_end, stderr=subprocess.PIPE, text=True, env=env)
    os.close(write_end)
    try:
        lines = []
        while "completed, " not in (line := runner.stderr.readline()) and line:
            lines.append(line)
        assert line, "".join(lines)  # entry 1 recorded; the runner waits to print its path
        edit_by_hand(out, lambda blocks: [*blocks, "\n".join(
            row for row in blocks[0].splitlines() if not row.startswith("id = ")).replace(
            'state = "completed"', 'state = "pending"').replace(
            f'run = "{entries(out)[0]["run"]}"', 'run = ""') + "\n"])
        with os.fdopen(read_end, "rb") as stdout:
            stdout.read()
        stderr = runner.stderr.read()
        assert runner.wait(timeout=120) == 0, stderr
    finally:
        runner.kill()
    first, added = entries(out)
    assert added["id"] and added["id"] != first["id"], added
    assert (first["state"], added["state"]) == ("completed", "completed")
    assert run_dirs(out) == {first["run"], added["run"]}
    assert "while it ran" not in stderr


def test_run_entry_measures_nothing_for_an_entry_without_id(bench):
    """An id that no entry has, or none at all (an entry queue.toml holds without one): one
    QueueError, and no run is started."""
    root, out = bench
    assert queue("add", root / "short.toml", "--sim", "--out", out).returncode == 0
    edit_by_hand(out, lambda blocks: ["\n".join(row for row in blocks[0].splitlines()
                                                if not row.startswith("id = ")) + "\n"])
    with PauseControl() as control:
        for entry_id in ("", "0badc0de"):
            with pytest.raises(QueueError, match=f"no entry has id '{entry_id}' any more"):
                run_entry(out, entry_id, control, progress=False)
    assert run_dirs(out) == set()


def test_queue_list_names_what_it_cannot_read(bench):
    """An entry missing a field, a run directory whose meta.json is no object, one whose
    meta.json is not JSON: each is its line's note, the rest is listed, exit 1; a queue file
    that is not TOML is one error line."""
    root, out = bench
    assert queue("add", root / "short.toml", root / "short.toml", root / "short.toml",
                 root / "short.toml", "--sim", "--out", out).returncode == 0
    for name, meta in (("run-a", "[1]"), ("run-b", "{not json")):
        (out / name).mkdir()
        for file in ("meta.json", "plan.json", "config.json"):
            (out / name / file).write_text("{}")
        (out / name / "readings.jsonl").write_text("")
        (out / name / "meta.json").write_text(meta)
    edit_by_hand(out, lambda blocks: [
        blocks[0].replace('run = ""', 'run = "run-a"'),
        blocks[1].replace("sim = true\n", ""),
        blocks[2].replace('run = ""', 'run = "run-b"'), blocks[3]])
    listed = queue("list", "--out", out)
    assert listed.returncode == 1 and listed.stderr == ""
    lines = listed.stdout.splitlines()
    assert len(lines) == 4
    assert lines[0].startswith("1  ") and "(cannot read: " in lines[0] and "run-a" in lines[0]
    assert lines[1] == f"2  cannot read: {queue_path(out)}: [entry[2]]: missing required key " \
                       f"'sim'"
    assert lines[2].startswith("3  ") and "damaged run directory" in lines[2]
    assert lines[3].startswith("4  ") and lines[3].endswith("  pending  -  0/3")
    queue_path(out).write_text("[[entry]\n")
    broken = queue("list", "--out", out)
    assert broken.returncode == 2
    assert "not a valid queue file" in one_line_error(broken.stderr)


def test_a_queue_file_without_ids_gets_them_at_its_first_change(tmp_path):
    """A queue.toml written without ids (as by an earlier gonio) reads as it is, and its
    first change gives every entry an id of its own, kept from then on."""
    written = [ENTRY, Entry(**{**ENTRY.__dict__, "plan": "queue/02/b.toml"})]
    queue_path(tmp_path).write_text(render(written).replace('id = ""\n', ""))
    assert [e.id for e in load(tmp_path)] == ["", ""]
    given = identify(tmp_path)
    assert all(e.id for e in given) and len({e.id for e in given}) == 2
    assert load(tmp_path) == given == identify(tmp_path)
    assert [Entry(**{**e.__dict__, "id": ""}) for e in given] == written


def test_two_entries_with_one_id_are_one_error(tmp_path):
    twice = [Entry(**{**ENTRY.__dict__, "id": "ab12"})] * 2
    queue_path(tmp_path).write_text(render(twice))
    with pytest.raises(QueueError, match=r"\[entry\[2\]\] id: 'ab12' is also entry\[1\]'s"):
        load(tmp_path)


ENTRY = Entry(plan="queue/01/a.toml", source="/p/a.toml", instrument="/p/i.toml", sim=True,
              planned=3, added_utc="2026-01-01T00:00:00.000+00:00")


def test_the_queue_file_reads_back_what_was_written(tmp_path):
    odd = 'quote " backslash \\ newline \n tab \t del \x7f bell \x07 unicode \u00e9\U0001f600'
    written = [ENTRY, Entry(**{**ENTRY.__dict__, "sim": ("pm100", "arm"), "state": "failed",
                               "run": "20260101T000000Z-a", "reason": odd})]
    queue_path(tmp_path).write_text(render(written), encoding="utf-8")
    assert load(tmp_path) == written
    assert load(tmp_path / "elsewhere") == []


@pytest.mark.parametrize(("change", "message"), [
    ({"state": "runnig"}, "[entry[2]] state: must be one of pending, running"),
    ({"planned": "3"}, "[entry[2]] planned: must be an integer"),
    ({"sim": 1}, "[entry[2]] sim: must be true, false or a list of device names"),
    ({"sim": []}, "[entry[2]] sim: must be true, false or a list of device names"),
    ({"state": "completed"}, "[entry[2]] run: missing: a completed entry names its run"),
    ({"run": "../elsewhere"}, "[entry[2]] run: must be the name of a run directory"),
    ({"stat": "pending"}, "[entry[2]]: unknown key 'stat'"),
    ({"plan": None}, "[entry[2]]: missing required key 'plan'"),
    ({"sim": None}, "[entry[2]]: missing required key 'sim'"),
])
def test_a_bad_entry_is_named_with_its_field(tmp_path, change, message):
    good = ENTRY.__dict__
    bad = {k: v for k, v in {**good, **change}.items() if v is not None}
    write_toml(queue_path(tmp_path), {"entry": [{**good, "sim": True}, bad]})
    with pytest.raises(QueueError) as info:
        load(tmp_path)
    assert str(info.value).startswith(f"{queue_path(tmp_path)}: {message}")


def test_not_toml_is_one_error(tmp_path):
    queue_path(tmp_path).write_text("[[entry]\n")
    with pytest.raises(QueueError, match="not a valid queue file"):
        load(tmp_path)


def test_the_next_entry_is_the_first_not_completed_nor_passed_over():
    states = ["completed", "failed", "running", "pending"]
    queued = [Entry(**{**ENTRY.__dict__, "state": s, "run": "r"}) for s in states]
    assert next_position(queued) == 2
    assert next_position(queued, {2}) == 3
    assert next_position(queued, {2, 3, 4}) is None
