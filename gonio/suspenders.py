"""Suspenders: conditions that hold a scan while they last and resume it when they clear, the
interrupted point measured again (the reading a suspender caught is discarded, not stored).

A plan's `[suspend]` table switches them on:

    [suspend]
    source_drift_share = 0.02  # a beam reading off the run's first one by more than this share
    saturated_burst = 3        # this many saturated readings in a row
    interlock = true           # a device reports its interlock (ESP emergency stop, a
                               # register map's `interlock` status bit)
    timeout_s = 600            # a suspension not cleared by then fails the run, with its reason
    recheck_s = 1              # how often a held run looks again

The source drift is seen in the plan's interleaved beam readings ([beam] every = N): a beam
reading beyond the share suspends the run before the next reading and is taken again until it
is back within the share of the first beam reading. A burst's last saturated reading is taken
again until it is not saturated. An interlock holds the run until every device that reports
one is ready again; the point is then measured from the start (move, settle, read).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

from gonio.fields import Fields


@dataclass(frozen=True)
class SuspendSpec:
    """The suspenders a plan asks for (None / False: off) and how long they may hold."""

    source_drift_share: float | None = None
    saturated_burst: int | None = None
    interlock: bool = False
    timeout_s: float = 600.0
    recheck_s: float = 1.0


def parse_suspend(f: Fields, beam_every: int) -> SuspendSpec:
    """The plan's [suspend] table (one error naming the field for a bad value); beam_every:
    the plan's [beam] every (the drift is seen in beam readings)."""
    spec = SuspendSpec(
        source_drift_share=f.number("source_drift_share", None, low=1e-6, high=1.0),
        saturated_burst=f.number("saturated_burst", None, low=1, high=1_000_000, integer=True),
        interlock=f.boolean("interlock", False),
        timeout_s=f.number("timeout_s", SuspendSpec.timeout_s, low=0.0, high=7 * 86400.0),
        recheck_s=f.number("recheck_s", SuspendSpec.recheck_s, low=0.001, high=3600.0),
    )
    f.done()
    if spec.source_drift_share is not None and not beam_every:
        raise f.fail("source_drift_share", "the drift is seen in interleaved beam readings: "
                                           "the plan needs [beam] every = N")
    return spec


class Watch:
    """Looks at each reading for what the suspenders object to; `stored` are the run's stored
    readings (a resumed run keeps its first beam reading as the drift reference)."""

    def __init__(self, spec: SuspendSpec, stored: Iterable[dict[str, Any]] = ()):
        self.spec = spec
        self.reference_w = next((float(r["power_w"]) for r in stored
                                 if r.get("kind") == "beam" and r.get("power_w") is not None),
                                None)
        self.saturated_run = 0  # saturated readings in a row, up to the last stored one

    def verdict(self, record: dict[str, Any]) -> str | None:
        """Why this reading must not be stored (a suspender holds the run), or None."""
        share = self.spec.source_drift_share
        if share is not None and record.get("kind") == "beam" and self.reference_w:
            ratio = record["power_w"] / self.reference_w
            if not abs(ratio - 1.0) <= share:  # NaN counts as drifted
                return (f"source drift: beam reading at {ratio:.4g} of the first one "
                        f"(allowed share {share:g})")
        burst = self.spec.saturated_burst
        if burst is not None and record["saturated"] and self.saturated_run + 1 >= burst:
            return f"{burst} saturated readings in a row"
        return None

    def accept(self, record: dict[str, Any]) -> None:
        """A reading was stored: it may be the drift reference and counts for bursts."""
        if self.reference_w is None and record.get("kind") == "beam" and record["power_w"] > 0:
            self.reference_w = float(record["power_w"])
        self.saturated_run = self.saturated_run + 1 if record["saturated"] else 0
