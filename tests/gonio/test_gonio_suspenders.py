"""Suspenders on the emulated bench: a source dip seen in a beam reading and an ESP emergency
stop each hold the run and resume it when they clear, and the run stores exactly the rows of
an undisturbed one (index, kind, positions, and at an instant time scale the values: a reading
thrown away does not count as a visit of the emulated detector); a condition that outlasts the
timeout fails the run with its reason. The faults begin on the run's (virtual) clock at the
prompted signature pass: when the undisturbed run reached it, the readings before it all
taken; the holds and the timeout count on that clock too."""

import os
import subprocess
import sys
from pathlib import Path

from gonio_testkit import ROOT, fast_config, write_plan

from gonio.errors import PlanError
from gonio.plan import parse_plan
from gonio.store import open_run
from gonio.suspenders import SuspendSpec, Watch

SUSPEND = {"source_drift_share": 0.02, "interlock": True, "timeout_s": 20.0, "recheck_s": 0.1}
PLAN = {"name": "held", "grid": [{"theta_i_deg": [20.0], "theta_o_deg": {
            "start": -60, "stop": 60, "step": 20}, "skip_forbidden": True}],
        "beam": {"every": 100}, "dark": {"every": 100}, "signature": {"pass": "prompted"},
        "suspend": SUSPEND}
COMPARED = ("index", "kind", "side", "point", "sample_deg", "arm_deg", "azimuth_deg",
            "elevation_deg", "power_w", "range_w", "saturated", "flags")


PROMPT = b"[c]ontinue or [a]bort?"


def start(folder, name: str, sim: dict, suspend=SUSPEND) -> subprocess.Popen:
    """`gonio scan --sim` of PLAN with the [sim] additions `sim`."""
    cfg = fast_config(pm100={"timeout_s": 10.0})  # no re-sent query: one visit per reading
    cfg["sim"]["sample"].update(multiple_scattering=False, diffraction=False)  # a quick start
    for key, table in sim.items():
        cfg["sim"].setdefault(key, {}).update(table)
    plan = write_plan(folder, {**PLAN, "suspend": suspend}, cfg, name=name)
    return subprocess.Popen([sys.executable, "-m", "gonio_cli", "scan", str(plan), "--sim",
                             "--out", str(folder / name), "--no-plot", "--no-progress"],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, env={**os.environ, "PYTHONPATH": str(ROOT)})


def answered(proc: subprocess.Popen) -> tuple[Path, int]:
    """Wait for the signature pass's prompt and answer it; the run directory and the exit
    status."""
    seen = b""
    while PROMPT not in seen:
        chunk = os.read(proc.stderr.fileno(), 4096)
        assert chunk, (seen + proc.communicate()[1]).decode()
        seen += chunk
    out, _ = proc.communicate(b"c\n", timeout=120)
    return Path(out.decode().split()[-1]), proc.returncode


def rows(run_dir):
    return [{k: row[k] for k in COMPARED} for row in open_run(run_dir).rows()]


def test_suspended_runs_store_the_undisturbed_rows_or_fail_past_the_timeout(tmp_path):
    calm_dir, code = answered(start(tmp_path, "calm", {}))
    assert code == 0
    calm_rows = open_run(calm_dir).rows()
    first_after_prompt = next(r["index"] for r in calm_rows if r["kind"] == "signature")
    # the faults begin where the run's clock stands at the prompt (an instant clock: the end of
    # the reading before it); the dip outlasts the rest of the run by 1.5 s
    begin = calm_rows[first_after_prompt - 1]["t_s"]
    dip_s = calm_rows[-1]["t_s"] - begin + 1.5
    faults = {"source": {"dip": {"start_s": begin, "duration_s": dip_s, "depth": 0.5}},
              "faults": {"esp": {"interlock": {"start_s": begin, "duration_s": 0.5}}}}
    held_dir, held_code = answered(start(tmp_path, "held", faults))
    long_dir, long_code = answered(start(
        tmp_path, "long", {"source": {"dip": {"start_s": begin, "duration_s": 600.0,
                                              "depth": 0.5}}},
        suspend={**SUSPEND, "timeout_s": 0.5}))

    # the emergency stop holds the first reading after the prompt, the dip the closing beam
    # reading; released, each is measured as if nothing had happened
    assert held_code == 0
    assert rows(held_dir) == rows(calm_dir)
    estop, dip = open_run(held_dir).meta["suspensions"]
    assert estop["index"] == first_after_prompt and "EMERGENCY STOP ACTIVATED" in estop["reason"]
    assert begin <= estop["t_s"] < estop["resumed_t_s"] and estop["resumed_t_s"] >= begin + 0.5
    assert dip["index"] == len(rows(calm_dir)) - 1
    assert dip["reason"].startswith("source drift: beam reading at 0.5")
    assert estop["resumed_t_s"] <= dip["t_s"] < dip["resumed_t_s"]
    assert dip["resumed_t_s"] >= begin + dip_s
    assert open_run(held_dir).meta["status"] == "completed"

    # a dip that outlasts the timeout fails the run with its reason, all but the held reading
    assert long_code == 1
    meta = open_run(long_dir).meta
    assert meta["status"] == "failed" and "not cleared within 0.5 s" in meta["reason"]
    assert "source drift" in meta["reason"] and meta["suspensions"][0]["resumed_t_s"] is None
    assert len(rows(long_dir)) == len(rows(calm_dir)) - 1


def test_a_saturated_burst_is_measured_again_and_counted_only_when_stored():
    watch = Watch(SuspendSpec(saturated_burst=3))
    saturated = {"kind": "sample", "saturated": True, "power_w": 1.0}
    for _ in range(2):
        assert watch.verdict(saturated) is None
        watch.accept(saturated)
    assert watch.verdict(saturated) == "3 saturated readings in a row"
    clear = {**saturated, "saturated": False}
    assert watch.verdict(clear) is None
    watch.accept(clear)
    assert watch.verdict(saturated) is None  # the burst starts again


def test_the_drift_reference_is_the_runs_first_beam_reading():
    stored = [{"kind": "dark", "power_w": 0.0}, {"kind": "beam", "power_w": 2.0e-3}]
    watch = Watch(SuspendSpec(source_drift_share=0.02), stored)
    assert watch.verdict({"kind": "beam", "power_w": 2.03e-3, "saturated": False}) is None
    assert "1.025 of the first" in watch.verdict({"kind": "beam", "power_w": 2.05e-3,
                                                   "saturated": False})
    assert watch.verdict({"kind": "sample", "power_w": 1e-9, "saturated": False}) is None


def test_suspend_fields_are_checked_with_one_error_naming_the_field():
    cases = [({"source_drift_share": 2.0}, "[suspend] source_drift_share"),
             ({"saturated_burst": 0}, "[suspend] saturated_burst"),
             ({"interlock": "yes"}, "[suspend] interlock"),
             ({"timeout_s": -1}, "[suspend] timeout_s"),
             ({"typo": 1}, "typo")]
    for table, named in cases:
        try:
            parse_plan({**PLAN, "suspend": table})
        except PlanError as exc:
            assert named in str(exc), str(exc)
        else:
            raise AssertionError(f"{table} accepted")
    no_beam = {k: v for k, v in PLAN.items() if k != "beam"}
    try:
        parse_plan(no_beam)
    except PlanError as exc:
        assert "source_drift_share" in str(exc) and "[beam] every" in str(exc)
    else:
        raise AssertionError("a drift share without beam readings accepted")
