"""Start or resume a scan: plan + config -> schedule -> (emulators) -> drivers -> engine -> store.

What `gonio scan` does, as a function the tests and bench scripts call too. Validation of
plan and config happens before any device is opened.
"""

from __future__ import annotations

import contextlib
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from drivers.base import Detector
from gonio.config import InstrumentConfig, load_config, parse_config
from gonio.control import RunStatus, serving
from gonio.device_kinds import endpoint_keys
from gonio.engine import Engine, Outcome, configure_detector
from gonio.errors import ConfigError, PlanError, RunError, Terminated
from gonio.events import EventBus, State, Subscriber
from gonio.instrument import build_instrument
from gonio.invalid_readings import InvalidReadings
from gonio.plan import Plan, Schedule, build_schedule, load_plan, parse_plan
from gonio.progress import Progress
from gonio.recorder import RunRecorder, record_end
from gonio.run_clock import RunClock
from gonio.run_control import PauseControl
from gonio.store import RunWriter, digest_problems, open_run
from gonio.suspenders import Watch

DetectorCheck = Callable[[np.ndarray, Detector], None]  # schedule readings, open detector
Started = Callable[[Path, str | None], None]  # the run directory, the control token


@dataclass
class ScanResult:
    """Where a scan went and how it ended."""

    path: Path
    outcome: Outcome


def instrument_path(plan: Plan, instrument: str | Path | None) -> Path:
    """--instrument, else the plan's own `instrument`, else a PlanError."""
    if instrument is not None:
        return Path(instrument)
    if plan.instrument is None:
        raise PlanError(f"{plan.path}: no instrument: give --instrument CFG or set "
                        f"`instrument = \"...\"` in the plan")
    return plan.instrument


@dataclass
class _Devices:
    """What to open: the config (pointed at emulators under --sim), its time scale, the
    emulated devices, the emulation's subscribers to the engine's events, the run's clock
    (None: the wall clock) and what the emulation records in the session as it starts."""

    config: InstrumentConfig
    time_scale: float = 1.0
    emulated: tuple[str, ...] = ()
    subscribers: tuple[Subscriber, ...] = ()
    clock: RunClock | None = None
    session: dict[str, Any] = field(default_factory=dict)


@contextmanager
def _devices(cfg: InstrumentConfig, sim: list[str] | bool, plan: Plan, t0_epoch: float,
             stored: np.ndarray, upcoming: np.ndarray, progress: bool | None,
             clock_start_s: float) -> Iterator[_Devices]:
    """The devices to open; under --sim the emulators, told the `stored` schedule rows (what
    an emulated detector of a resumed run has measured already), the `upcoming` ones (whose
    tables they build before serving, with a progress line unless progress is False) and,
    all emulated, the run's time this session starts at (clock_start_s)."""
    if sim is False:
        yield _Devices(cfg)
        return
    from gonio.simulate import simulation, visit  # only --sim touches sim

    with simulation(cfg, None if sim is True else sim, plan.raw.get("sample"), t0_epoch,
                    [visit(row, cfg.axes) for row in stored], upcoming, progress,
                    clock_start_s) as s:
        yield _Devices(s.config, s.time_scale, tuple(s.devices), (s.telemetry,), s.clock,
                       s.session_start())


def operator_prompts(plan: Plan, readings: np.ndarray, todo: Sequence[int]) -> dict[int, str]:
    """The operator prompts of the readings still to measure (`todo`), by index: before the
    first of them in a prompted signature pass, the prompt to remove the sample."""
    sig = plan.signature
    rest = readings[list(todo)]
    signature = rest[rest["kind"] == "signature"]
    if sig is None or sig.mode != "prompted" or not len(signature):
        return {}
    return {int(signature["index"][0]): f"signature pass: remove the sample (nothing but the "
                                        f"bench in the beam) for the next {len(signature)} "
                                        f"readings"}


def _run(make_writer: Callable[[], RunWriter], plan: Plan, cfg: InstrumentConfig,
         sched: Schedule, sim: list[str] | bool, progress: bool | None,
         control: PauseControl | None, t0_epoch: float, stored: Sequence[dict] = (),
         check: DetectorCheck | None = None, session: dict[str, Any] | None = None,
         channel: bool = False, started: Started | None = None,
         created: Callable[[Path], None] | None = None, clock_start_s: float = 0.0
         ) -> ScanResult:
    """Open the devices, set the detector's wavelength and averaging and check it (`check`),
    then open the run (so a device that cannot be opened, a setting it refuses, such as a
    wavelength its sensor head cannot take, or a failed check leaves no new run behind), and
    measure what is left
    of the schedule (`stored`: the readings stored already; the run started at t0_epoch).
    session: more for meta.json's record of this session; channel: serve the control channel
    (gonio.control) in the run directory; started: told the run directory once it exists, and
    the control channel's token (None: no channel), before the engine starts (`gonio scan
    --watch`); created: told the run directory as soon as it exists, before any reading is
    measured (the queue records it there). The run's signal handling (`control`) starts
    before the run directory is made; a signal while it is made acts once it exists, and one
    that ends the run before the engine takes over is recorded there as the run's end
    (aborted, and why), so whatever its moment a signal leaves no run without its ending.
    Once the run has ended, signals are ignored until the devices are closed.
    clock_start_s: the run's time this session starts at on an all-emulated bench's virtual
    clock (resume_clock_s)."""
    control = control or PauseControl()
    stored_at = [row["index"] for row in stored]
    done, upcoming = sched.readings[stored_at], np.delete(sched.readings, stored_at)
    with control.held_until_closed(), \
            _devices(cfg, sim, plan, t0_epoch, done, upcoming, progress, clock_start_s) as dev, \
            build_instrument(dev.config, dev.time_scale) as inst:
        configure_detector(inst, plan, None)
        if check is not None:
            check(sched.readings, inst.detector)
        with control:
            writer = None
            try:
                with control.deferring():
                    writer = make_writer()
                if created is not None:
                    created(writer.path)
                swapped = identity_changes(writer.meta["sessions"], inst.devices)
                todo = writer.todo(len(sched))
                status = RunStatus()
                bar = Progress(len(sched), writer.stored, plan.name,
                               disable=None if progress is None else not progress)
                bus = EventBus([RunRecorder(writer), bar, *dev.subscribers, status,
                                inst.record_lines])
                engine = Engine(inst, plan, sched.readings, todo, bus, stored=writer.stored,
                                control=control, t0_epoch=writer.meta["t0_epoch"],
                                clock=dev.clock,
                                prompts=operator_prompts(plan, sched.readings, todo),
                                invalid=InvalidReadings(inst.detector.name, len(sched),
                                                        plan.max_invalid_share, stored),
                                watch=Watch(plan.suspend, stored) if plan.suspend else None,
                                session={"sim": list(dev.emulated),
                                         "endpoints": {n: d.endpoint
                                                       for n, d in dev.config.devices.items()},
                                         "devices": inst.devices, **dev.session,
                                **({"clock": "virtual", "clock_start_s": clock_start_s}
                                   if dev.clock is not None else {}),
                                         **({"identity_changes": swapped} if swapped else {}),
                                         **(session or {})})
                with serving(writer.path, control, status) if channel \
                        else contextlib.nullcontext() as server:
                    if started is not None:
                        started(writer.path, server.token if server else None)
                    return ScanResult(writer.path, engine.run())
            except (Terminated, KeyboardInterrupt) as exc:
                if writer is None:
                    raise
                return ScanResult(writer.path, _ended_unstarted(writer, control, exc))
            finally:
                if writer is not None:
                    writer.close()


def _ended_unstarted(writer: RunWriter, control: PauseControl,
                     exc: Terminated | KeyboardInterrupt) -> Outcome:
    """The run ended by a signal or an abort once its directory existed but before the engine
    took it over (nothing has moved): recorded as aborted, with why."""
    control.hold()
    control.enter(State.STOPPING)
    control.enter(State.ABORTED)
    signum = exc.signum if isinstance(exc, Terminated) else None
    why = str(exc) if signum else control.abort_reason or "aborted by the user (Ctrl-C)"
    reason = f"{why} before {'this session' if writer.stored else 'the run'}'s first reading"
    return Outcome("aborted", reason, writer.stored, signum,
                   unrecorded=record_end(writer, "aborted", reason))


def new_scan(plan_path: str | Path, instrument: str | Path | None = None,
             sim: list[str] | bool = False, out: str | Path = "runs",
             progress: bool | None = None, control: PauseControl | None = None,
             calibration: dict | None = None, time_scale: float | None = None,
             sample_id: str | None = None, check: DetectorCheck | None = None,
             warn: Callable[[str], None] | None = None, channel: bool = False,
             started: Started | None = None,
             created: Callable[[Path], None] | None = None) -> ScanResult:
    """Validate plan and config, create a run directory and measure the plan into it.

    sim: False (real devices), True (emulate every device) or a list of device / role names;
    calibration: what meta.json records about the calibration file to use (or None);
    time_scale: replaces the config's [sim] time_scale (emulated runs only);
    sample_id: replaces the plan's [sample] id (the stored plan and the record carry it);
    check: called with the schedule's readings and the open detector before the run directory
    exists and before any motion (the scan command checks the calibration's ranges there);
    warn: told, once the devices are open and checked and before any motion, what the run
    will lack that reduction needs (undescribed);
    channel: serve the control channel in the run directory (gonio.control; token on stderr);
    started: told the run directory once it exists and the control channel's token (None:
    none), before any reading.
    created: told the run directory as soon as it exists, before any reading is measured
    (the queue records it there).
    """
    plan = load_plan(plan_path)
    if sample_id is not None:
        plan = with_sample_id(plan, sample_id)
    cfg_path = instrument_path(plan, instrument)
    cfg = scaled(load_config(cfg_path), sim, time_scale)
    sched = schedule_for(plan, cfg, sim)
    seeds = {"sim": cfg.sim.get("seed", 0)} if sim is not False else {}
    meta = {"plan_name": plan.name, "calibrates": plan.calibrates,
            "instrument_name": cfg.name, "planned": len(sched),
            "estimate_s": sched.estimate_s, "naive_estimate_s": sched.naive_estimate_s,
            "sim": sim if isinstance(sim, list) else bool(sim), "seeds": seeds,
            "time_scale": cfg.sim.get("time_scale", 1.0) if sim is not False else 1.0,
            "calibration": calibration, "t0_epoch": time.time(),
            "optics": cfg.optics.to_json() if cfg.optics else None,
            "sample": plan.sample.to_json() if plan.sample else None}
    return _run(lambda: RunWriter.create(Path(out), plan.name, plan.path, cfg.path, plan.raw,
                                         cfg.raw, meta), plan, cfg, sched, sim, progress, control,
                meta["t0_epoch"], check=_then_warn(check, undescribed(plan, cfg), warn),
                channel=channel, started=started, created=created)


def scaled(cfg: InstrumentConfig, sim: list[str] | bool, time_scale: float | None
           ) -> InstrumentConfig:
    """The config with `--time-scale` as its [sim] time_scale (None: as it is); a ConfigError
    for a run with no emulated device (sim False)."""
    if time_scale is None:
        return cfg
    if sim is False:
        raise ConfigError("--time-scale applies to emulated devices: use it with --sim")
    from gonio.simulate import with_time_scale

    return with_time_scale(cfg, time_scale)


def schedule_for(plan: Plan, cfg: InstrumentConfig, sim: list[str] | bool) -> Schedule:
    """The plan's schedule on the instrument, once plan, config and --sim's device names
    are checked (PlanError / ConfigError): what a scan checks before any run directory."""
    sched = build_schedule(plan, cfg)
    if isinstance(sim, list):
        from gonio.simulate import resolve_devices

        resolve_devices(cfg, sim)
    return sched


def _then_warn(check: DetectorCheck | None, texts: list[str],
               warn: Callable[[str], None] | None) -> DetectorCheck:
    """The detector check, then the warnings: once every device is open and has passed, so
    no warning precedes an error that stops the scan anyway."""
    def checked(readings: np.ndarray, detector: Detector) -> None:
        if check is not None:
            check(readings, detector)
        for text in texts if warn else ():
            warn(text)
    return checked


def undescribed(plan: Plan, cfg: InstrumentConfig) -> list[str]:
    """What a run of this plan on this instrument will lack that reduction needs (the plan's
    [sample], the config's [optics]); the scan itself can go ahead."""
    out = []
    if plan.sample is None:
        out.append(f"{plan.path} has no [sample] table (id, kind, eta): the run will not "
                   f"reduce until the plan says what is measured")
    if cfg.optics is None:
        out.append(f"{cfg.path} has no [optics] table: the run reduces only with a "
                   f"calibration that measured the aperture")
    return out


def with_sample_id(plan: Plan, sample_id: str) -> Plan:
    """The plan with its [sample] id replaced (`gonio scan --sample-id`)."""
    if plan.sample is None:
        raise PlanError(f"{plan.path}: --sample-id {sample_id!r} needs a [sample] table in the "
                        f"plan (id, kind, eta: what is measured)")
    raw = {**plan.raw, "sample": {**plan.raw["sample"], "id": sample_id}}
    return parse_plan(raw, plan.path)


def resume_scan(run_dir: str | Path, instrument: str | Path | None = None,
                sim: list[str] | bool | None = None, progress: bool | None = None,
                control: PauseControl | None = None,
                plan_path: str | Path | None = None, channel: bool = False,
                started: Started | None = None) -> ScanResult:
    """Continue a run after its last stored reading (first measuring any a repair dropped or
    a cut file lost: a completed run that lost readings is finished this way),
    with the plan and config it started with, both checked against their digests.

    instrument: a config to use instead of the stored one, differing from it in device
    endpoints only (recorded in the session). sim: None = as the run was started.
    plan_path: a plan file that must say what the stored plan says (`same_plan`);
    channel, started: as for new_scan.
    """
    run = open_run(run_dir)
    lines = run.resumable_lines()
    if plan_path is not None:
        same_plan(plan_path, run.plan, run.path)
    plan = parse_plan(run.plan, run.path / "plan.toml")
    session: dict[str, Any] = {}
    if instrument is None:
        cfg = parse_config(run.config, run.path / "instrument.toml")
    else:
        cfg = load_config(instrument)
        session = _endpoint_changes(run.config, cfg.raw, instrument, run.path)
    problems = digest_problems(run, cfg.raw)
    if problems:
        raise RunError(f"{run.path}: {'; '.join(problems)}; cannot resume")
    sched = build_schedule(plan, cfg)
    if sim is None:
        sim = run.meta.get("sim", False)
    invalid = InvalidReadings(cfg.detector.device, len(sched), plan.max_invalid_share,
                              lines.rows)
    if invalid.too_many():  # a resume would stop at its first reading, after moving
        raise RunError(f"{run.path}: cannot resume: its stored readings end it: "
                       f"{invalid.too_many()}; once that is fixed, start a new scan")
    if len(lines.rows) >= len(sched):  # killed after its last reading
        status, reason = ("failed", invalid.none_valid()) if invalid.none_valid() else (
            "completed", "")
        with contextlib.closing(RunWriter.resume(run.path)) as writer:
            writer.set_status(status, reason)
        return ScanResult(run.path, Outcome(status, reason, len(lines.rows),
                                            resumable=not reason))
    return _run(lambda: RunWriter.resume(run.path), plan, cfg, sched, sim, progress, control,
                run.meta["t0_epoch"], stored=lines.rows, session=session, channel=channel,
                started=started, clock_start_s=resume_clock_s(run.meta, lines.rows))


def resume_clock_s(meta: dict[str, Any], stored: Sequence[dict]) -> float:
    """Where a resumed run's virtual clock goes on from: the latest of its sessions' recorded
    ends (`clock_end_s`) and its stored readings' latest t_s (a session killed outright records
    no end; a repaired run's refilled readings come last in time, not in index)."""
    ends = [float(s["clock_end_s"]) for s in meta.get("sessions", []) if "clock_end_s" in s]
    return max([*ends, *(float(row["t_s"]) for row in stored)], default=0.0)


_MISSING = object()
ENDPOINT_KEYS = endpoint_keys()


def _flat(data: dict, prefix: str = "") -> dict[str, Any]:
    """A nested dict as {dotted.path: value} (lists are values)."""
    out: dict[str, Any] = {}
    for key, value in data.items():
        if isinstance(value, dict):
            out.update(_flat(value, f"{prefix}{key}."))
        else:
            out[f"{prefix}{key}"] = value
    return out


def _differing(a: dict, b: dict) -> dict[str, tuple[Any, Any]]:
    """Dotted paths where two nested dicts differ, with both values (_MISSING if absent)."""
    fa, fb = _flat(a), _flat(b)
    return {k: (fa.get(k, _MISSING), fb.get(k, _MISSING)) for k in sorted(fa.keys() | fb.keys())
            if fa.get(k, _MISSING) != fb.get(k, _MISSING)}


def _endpoint_changes(stored: dict, new: dict, cfg_path: str | Path,
                      run_path: Path) -> dict[str, Any]:
    """RunError unless the config differs from the run's in device endpoints only (register
    maps are compared by content elsewhere); the endpoint changes for the session record."""
    changes, refused = {}, []
    for key, (was, now) in _differing(stored, new).items():
        parts = key.split(".")
        if len(parts) == 3 and parts[0] == "devices" and parts[2] == "register_map":
            continue
        if len(parts) == 3 and parts[0] == "devices" and parts[2] in ENDPOINT_KEYS:
            changes[key] = {"from": None if was is _MISSING else was,
                            "to": None if now is _MISSING else now}
        else:
            refused.append(key)
    if refused:
        raise RunError(f"{cfg_path}: differs from the config {run_path} was started with in "
                       f"{', '.join(refused)}; on resume only device endpoints "
                       f"({', '.join(ENDPOINT_KEYS)}) may change")
    return {"endpoint_changes": changes} if changes else {}


def identity_changes(sessions: list[dict[str, Any]], devices: dict[str, dict[str, Any]]
                     ) -> dict[str, dict[str, Any]]:
    """Devices whose reported identity differs from the last session's record of it (both
    known), each warned about on stderr: {name: {"from": identity, "to": identity}}."""
    before = next((s["devices"] for s in reversed(sessions) if s.get("devices")), {})
    out = {}
    for name, dev in devices.items():
        was, now = before.get(name, {}).get("identity"), dev.get("identity")
        if was and now and was != now:
            out[name] = {"from": was, "to": now}
            differ = ", ".join(f"{k} {was.get(k)!r} -> {now.get(k)!r}"
                               for k in sorted(was.keys() | now.keys()) if was.get(k) != now.get(k))
            print(f"gonio scan: warning: device {name!r} reports another identity than in the "
                  f"last session ({differ}); recorded in meta.json", file=sys.stderr)
    return out


def same_plan(plan_path: str | Path, stored: dict, run_path: Path) -> None:
    """RunError unless the plan file parses to the run's stored plan (plan.json): the TOML
    dicts compared, so comments and formatting do not count, and `instrument` as written."""
    differ = _differing(load_plan(plan_path).raw, stored)
    if differ:
        raise RunError(f"{plan_path}: not the plan {run_path} was started with (differs in "
                       f"{', '.join(differ)}); resume without PLAN to use the stored one")
