"""`gonio scan PLAN`: run a plan on an instrument (real, emulated, or mixed) into a run directory.

Once a run directory exists it is the last line printed on stdout, whatever the outcome; while
it measures, RUN_DIR/control.sock serves the control channel (its token on stderr). The
exit status: 0 completed, 1 failed, 2 bad input or a device that cannot be used (a plan or
config that does not load, a port another process holds, a device that cannot be opened or
refuses a setting: before anything moves), 130 aborted by Ctrl-C, 128 + N ended by signal N
(SIGTERM, SIGHUP). A completed run whose directory refuses to record its end exits 1 too (one
warning line says so and where its readings are); once a run has ended, no later signal
changes its exit status.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from gonio.errors import GonioError, os_error_text

if TYPE_CHECKING:
    import numpy as np

    from drivers.base import Detector
    from gonio.runner import DetectorCheck, ScanResult


def _sim_names(value: str) -> list[str]:
    return [v for v in value.split(",") if v]


def add_sim_option(p: argparse.ArgumentParser) -> None:
    """--sim [NAMES]: emulate every device, or the named ones (scan, queue add)."""
    p.add_argument("--sim", nargs="?", const=True, default=None, type=_sim_names,
                   metavar="NAMES",
                   help="emulate every device, or only the named devices/roles "
                        "(comma-separated, e.g. --sim detector)")


def plan_given_to_sim(sim: list[str] | bool | None) -> tuple[str | None, list[str] | bool | None]:
    """`--sim PLAN.toml`: argparse hands the plan to --sim's optional NAMES; this takes it
    back as (the plan, sim = True), else (None, sim as it was)."""
    if isinstance(sim, list) and len(sim) == 1 and sim[0].endswith(".toml"):
        return sim[0], True
    return None, sim


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the `scan` verb."""
    p = subparsers.add_parser("scan", help="run a scan plan and record it",
                              description=__doc__)
    p.add_argument("plan", nargs="?",
                   help="plan TOML file (with --resume: optional, must match the run's plan)")
    p.add_argument("--instrument", metavar="CFG",
                   help="instrument config (default: the plan's `instrument`)")
    add_sim_option(p)
    p.add_argument("--time-scale", type=float, metavar="X",
                   help="with --sim: virtual seconds per real second (inf = instant moves), "
                        "instead of the config's [sim] time_scale")
    p.add_argument("--out", default="runs", metavar="DIR",
                   help="where run directories go (default: ./runs)")
    p.add_argument("--resume", metavar="RUN", help="continue an interrupted run")
    p.add_argument("--calibration", metavar="FILE",
                   help="calibration file to record in the run (used by reduce and fit); "
                   "what it applies is printed before any motion")
    p.add_argument("--sample-id", metavar="ID",
                   help="the measured sample's id, instead of the plan's [sample] id")
    p.add_argument("--no-plot", action="store_true", help="do not write plot.png")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--watch", action="store_true",
                   help="follow the run in a browser page beside the scan (gonio watch, "
                        "given the session's control token); its URL with the page's key goes "
                        "to stderr")
    p.set_defaults(func=run)


def _plot(run_dir, verb: str) -> None:
    """plot.png: the calibrated BSDF plot (calibration.plot); for a run that cannot be reduced
    (no beam readings, say) the quick look at raw power instead."""
    from calibration.plot import plot_run

    try:
        plot_run(run_dir)
    except GonioError as exc:
        from gonio.quicklook import write_quicklook

        write_quicklook(run_dir)
        print(f"{verb}: note: plot.png shows raw power ({exc})", file=sys.stderr)


def _watch(run_dir: Path, token: str | None) -> subprocess.Popen | None:
    """Start the live view beside the scan (None, with a warning, if it cannot start: the
    scan goes on without it)."""
    from gonio_cli.commands.watch import start_beside

    try:
        return start_beside(run_dir, token)
    except OSError as exc:
        print(f"gonio scan: warning: no live view: {os_error_text(exc)}", file=sys.stderr)
        return None


def _covers(path: str) -> DetectorCheck:
    """The check, once the detector is open and before any motion, that the calibration file
    covers every range the schedule can read on (calibration.coverage); once it does, what the
    file applies is printed (stderr, calibration.calsummary)."""
    from calibration import calfile, coverage
    from calibration.calsummary import applied

    cal = calfile.load(path)

    def check(readings: np.ndarray, detector: Detector) -> None:
        coverage.require(cal, path, readings, detector.full_scales_w())
        for line in applied(cal, str(Path(path).resolve())):
            print(f"gonio scan: {line}", file=sys.stderr)

    return check


def run(args: argparse.Namespace) -> int:
    """Start or resume the scan; exit 0 when it completed."""
    from gonio.runner import new_scan, resume_scan

    progress = False if args.no_progress else None
    viewers: list = []
    started = (lambda path, token: viewers.append(_watch(path, token))) if args.watch else None
    if args.plan is None:
        args.plan, args.sim = plan_given_to_sim(args.sim)
    if args.resume:
        if args.calibration or args.time_scale is not None or args.sample_id:
            raise GonioError("--resume RUN continues a run as it was started: "
                             "give no --calibration, --time-scale or --sample-id with it")
        result = resume_scan(args.resume, args.instrument, args.sim, progress=progress,
                             plan_path=args.plan, channel=True, started=started)
    else:
        if not args.plan:
            raise GonioError("a PLAN file is needed (or --resume RUN)")
        calibration, check = None, None
        if args.calibration:
            from calibration.calfile import reference

            calibration, check = reference(args.calibration), _covers(args.calibration)
        result = new_scan(args.plan, args.instrument, args.sim or False, args.out,
                          progress=progress, calibration=calibration,
                          time_scale=args.time_scale, sample_id=args.sample_id, check=check,
                          warn=warner("gonio scan"), channel=True, started=started)
    for viewer in viewers:
        if viewer is not None:
            viewer.stdin.close()  # the viewer ends once an open page has shown the run's end
    return report(result, not args.no_plot, "gonio scan")


def warner(verb: str) -> Callable[[str], None]:
    """What prints a scan's warnings on stderr, as `VERB: warning: ...`."""
    return lambda text: print(f"{verb}: warning: {text}", file=sys.stderr)


def report(result: ScanResult, plot: bool, verb: str) -> int:
    """After a scan (or a queued one): plot.png if `plot` and readings were stored, how the
    run ended on stderr, its directory on stdout; the exit status (see the module doc)."""
    outcome = result.outcome
    plotted = False
    if plot and outcome.done:
        try:
            _plot(result.path, verb)
            plotted = True
        except Exception as exc:  # the data are stored; a plot problem must not hide the run
            print(f"{verb}: warning: no plot: {type(exc).__name__}: {exc}", file=sys.stderr)
        except KeyboardInterrupt:
            print(f"{verb}: warning: no plot: interrupted", file=sys.stderr)
    if outcome.unrecorded:
        print(f"{verb}: warning: the run's end ({outcome.status}) is not recorded: "
              f"{outcome.unrecorded}; its {outcome.done} readings are stored in "
              f"{result.path / 'readings.jsonl'} (once the directory takes writes, `gonio scan "
              f"--resume {result.path}` records it)", file=sys.stderr)
    if outcome.status != "completed":
        again = ("" if outcome.status != "failed"
                 else f" (once that is fixed, `gonio scan --resume {result.path}` continues it)"
                 if outcome.resumable else " (the readings stored stopped it: once that is "
                 "fixed, start a new scan)")
        print(f"{verb}: run {outcome.status} after {outcome.done} readings: "
              f"{outcome.reason}{again}", file=sys.stderr)
    else:
        plotted_to = f"; plot {result.path / 'plot.png'}" if plotted else ""
        print(f"{verb}: completed, {outcome.done} readings stored{plotted_to}", file=sys.stderr)
    print(result.path, flush=True)
    if outcome.signum:
        return 128 + outcome.signum
    if outcome.unrecorded and outcome.status == "completed":
        return 1
    return {"completed": 0, "aborted": 130}.get(outcome.status, 1)
