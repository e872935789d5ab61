"""The multiple-scattering table planes a bench's readings need: built before the first reading
(Bench.prepare, with progress), or counted and timed for `gonio plan --sim` (estimate, with
the time evaluating every reading once takes, which prepare spends on a warm cache too).

A reading's power is the aperture integral of the sample's integrand, whose multiple-scattering
term interpolates HigherOrderLobe's tables and walks a plane the first time a pair needs it:
minutes for the emulated Walter samples' 2^24 walks, too long for a device's reply. prepare
evaluates every reading ahead by the readings' own path with the sample collecting the planes
it misses instead of walking them (Sample.collecting), reads those the store holds, walks the
rest, and evaluates again the readings that missed any until none does: the evaluation's one
choice made on values (a negligible probe ends it, sim.bench.scene) then sees the values the
reading will, so exactly the planes the readings ask for are built.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

#: prepare's progress: told (planes walked, planes to walk) before the first walk and after
#: each (planes to walk grows when a second evaluation finds more).
Progress = Callable[[int, int], None]
#: estimate times at most this many of the planes to walk (spread over them) and scales.
TIMED_PLANES = 4


@dataclass
class TablesPrepared:
    """What prepare did on `bench`: planes the readings need that were not in memory, how many
    of them the store held (read) and how many were walked (walks each), in `seconds`; `held`,
    the planes the bench's sample held as prepare ended, from which record() counts those
    built later."""

    planes: int = 0
    read: int = 0
    walked: int = 0
    walks: int = 0
    seconds: float = 0.0
    bench: Any = field(default=None, repr=False)
    held: int = 0

    def record(self) -> dict[str, float]:
        """The record for a session's meta.json: what prepare did, and `in_readings`, the
        planes built since inside a reading (a position the plan did not foresee, such as a
        stage's repeatability scatter crossing into another plane)."""
        return {"planes": self.planes, "read": self.read, "walked": self.walked,
                "walks": self.walks, "seconds": self.seconds,
                "in_readings": built(self.bench) - self.held}


@dataclass(frozen=True)
class TablesEstimate:
    """Planes the readings need that the cache does not hold, walks each, the seconds walking
    them takes on this machine now (0 with none to walk), and `evaluate_s`, the seconds
    evaluating every reading once took here: what prepare spends even on a warm cache."""

    planes: int
    walks: int
    seconds: float
    evaluate_s: float = 0.0


def places(bench, positions: Iterable[Mapping[str, float]]) -> list[dict[str, float]]:
    """The distinct true positions (reported plus the alignment's offsets, no move's scatter)
    of the readings at `positions` that see the sample: retracted ones (beam, dark, signature)
    need no table."""
    out: dict[tuple, dict[str, float]] = {}
    for where in positions:
        place = bench.alignment.placed(where)
        if not bench.retracted(place["sample"]):
            out.setdefault(tuple(sorted(place.items())), place)
    return list(out.values())


def _missed(bench, pending: list[dict[str, float]]
            ) -> tuple[dict[object, set], list[dict[str, float]]]:
    """(the planes the readings at `pending` miss, by lobe; those readings)."""
    wanted: dict[object, set] = {}
    again = []
    for place in pending:
        with bench.sample.collecting() as missed:
            bench.scattered_fraction(place)
        if any(missed.values()):
            again.append(place)
            for lobe, addresses in missed.items():
                wanted.setdefault(lobe, set()).update(addresses)
    return wanted, again


def built(bench) -> int:
    """Table planes the bench's sample has built so far (walked or read), over its lobes."""
    return sum(lobe.planes_built for lobe in bench.sample.table_lobes())


def prepare(bench, positions: Iterable[Mapping[str, float]],
            progress: Progress | None = None) -> TablesPrepared:
    """Build every table plane the readings at `positions` (reported stage positions by role)
    will ask for: read from the store where it holds them, else walked (told to `progress`)."""
    start = time.perf_counter()
    report = TablesPrepared(walks=bench.sample.spec.ms_walks, bench=bench)
    pending = places(bench, positions) if bench.sample.tabulated else []  # no tables
    to_walk: list[tuple[object, tuple]] = []
    while pending:
        wanted, pending = _missed(bench, pending)
        for lobe, addresses in wanted.items():
            for address in sorted(addresses):
                report.planes += 1
                if lobe.build_at(address, walk=False):
                    report.read += 1
                else:
                    to_walk.append((lobe, address))
        if to_walk and progress is not None:
            progress(report.walked, report.walked + len(to_walk))
        while to_walk:
            lobe, address = to_walk.pop(0)
            lobe.build_at(address)
            report.walked += 1
            if progress is not None:
                progress(report.walked, report.walked + len(to_walk))
    report.seconds = time.perf_counter() - start
    report.held = built(bench)
    return report


def estimate(bench, positions: Iterable[Mapping[str, float]]) -> TablesEstimate:
    """The planes prepare would walk for readings at `positions` and their time, from
    TIMED_PLANES of them timed now (HigherOrderLobe.walk_seconds). One evaluation of each
    reading: planes behind a probe that the missing ones make look negligible are not
    counted (prepare's second evaluation finds them)."""
    walks = bench.sample.spec.ms_walks
    if not bench.sample.tabulated:
        return TablesEstimate(0, walks, 0.0)
    start = time.perf_counter()
    wanted, _ = _missed(bench, places(bench, positions))  # prepare's first evaluation
    evaluate_s = time.perf_counter() - start
    to_walk = [(lobe, address) for lobe, addresses in wanted.items()
               for address in sorted(addresses) if not lobe.build_at(address, walk=False)]
    if not to_walk:
        return TablesEstimate(0, walks, 0.0, evaluate_s)
    step = max(1, len(to_walk) // TIMED_PLANES)
    timed = [lobe.walk_seconds(address) for lobe, address in to_walk[::step][:TIMED_PLANES]]
    return TablesEstimate(len(to_walk), walks, len(to_walk) * sum(timed) / len(timed),
                          evaluate_s)
