"""What a scan engine tells the world: its state and typed events, and the bus that delivers them.

The engine publishes; the run store, the progress bar, the hardware-in-the-loop position feed,
the emulators' telemetry and the control channel subscribe (gonio.runner wires them). A
subscriber is any callable taking one event. Delivery is synchronous, on the engine's thread,
in subscription order; a subscriber that raises stops that event there (later subscribers do
not see it) and the exception ends the run as any failure at that point does: the run store
subscribes first, so a reading the disk refused is seen by nobody else and fails the run. The
end-of-run events (Stopping, Stopped) reach every subscriber; the first exception is raised
after the last one.
"""

from __future__ import annotations

import enum
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any, ClassVar


class State(enum.Enum):
    """The engine's state (the control channel reports its value)."""

    STARTING = "starting"
    RUNNING = "running"
    PAUSING = "pausing"  # a pause is asked for: it acts before the next reading
    PAUSED = "paused"
    SUSPENDED = "suspended"  # a suspender holds the run until its condition clears
    STOPPING = "stopping"
    COMPLETED = "completed"
    ABORTED = "aborted"
    FAILED = "failed"

    @property
    def final(self) -> bool:
        """True once the run has ended."""
        return self in (State.COMPLETED, State.ABORTED, State.FAILED)


@dataclass
class Suspension:
    """A suspender held the run at reading `index` from `t_s` (run seconds) for `reason`;
    resumed_t_s is when it cleared (None while it holds, or if it never did)."""

    reason: str
    index: int
    t_s: float
    resumed_t_s: float | None = None

    def to_json(self) -> dict[str, Any]:
        """The record meta.json keeps under `suspensions`."""
        return {"reason": self.reason, "index": self.index, "t_s": self.t_s,
                "resumed_t_s": self.resumed_t_s}


@dataclass(frozen=True)
class RunStarted:
    """A session starts: `planned` readings in the schedule, `stored` of them already stored,
    `todo` the indices this session measures in order; `session` what meta.json's session
    record starts with (emulated devices, endpoints, identities...)."""

    planned: int
    stored: int
    todo: tuple[int, ...]
    session: dict[str, Any]


@dataclass(frozen=True)
class Moved:
    """Every axis has arrived for reading `index`; `positions` are the stage positions the
    axes reported, {role: deg}, before the detector is read."""

    index: int
    positions: dict[str, float]


@dataclass(frozen=True)
class ReadingStored:
    """A reading to record: `record` is its line of readings.jsonl, `row` its schedule row.
    The run store (first subscriber) stores it; whoever comes after sees a stored reading."""

    record: dict[str, Any]
    row: Any


@dataclass(frozen=True)
class ReadingDiscarded:
    """A reading was taken at schedule row `row` and thrown away (`reason`): a suspender
    caught it, and the point is measured again."""

    row: Any
    reason: str


@dataclass(frozen=True)
class Paused:
    """The run is paused before reading `index` (`reason`: who asked)."""

    index: int
    reason: str


@dataclass(frozen=True)
class Resumed:
    """The run goes on before reading `index`: after a pause (suspension None) or after a
    suspension that cleared (its resumed_t_s set)."""

    index: int
    suspension: Suspension | None = None


@dataclass(frozen=True)
class Suspended:
    """A suspender holds the run (see Suspension)."""

    suspension: Suspension


@dataclass(frozen=True)
class Stopping:
    """The run is ending with `status` ("completed", "aborted", "failed") and `reason`.
    Subscribers may add to `session`, what this session's record in meta.json gets (the
    emulators add the faults they injected); the run store makes every reading durable here,
    and a disk that refuses fails a completing run."""

    status: str
    reason: str
    session: dict[str, Any] = field(default_factory=dict)
    to_every_subscriber: ClassVar[bool] = True


@dataclass(frozen=True)
class Stopped:
    """The run has ended: `status`, `reason`, `done` readings stored in all, the axes that
    could not be stopped ({role: why}) and the session additions gathered at Stopping.
    The store's subscriber adds to `unrecorded` why meta.json could not record the end (the
    engine's outcome carries it)."""

    status: str
    reason: str
    done: int
    unstopped: dict[str, str]
    session: dict[str, Any]
    unrecorded: list[str] = field(default_factory=list)
    to_every_subscriber: ClassVar[bool] = True


Event = (RunStarted | Moved | ReadingStored | ReadingDiscarded | Paused | Resumed | Suspended
         | Stopping | Stopped)
Subscriber = Callable[[Any], None]


class EventBus:
    """Delivers each published event to every subscriber, in subscription order."""

    def __init__(self, subscribers: Iterable[Subscriber] = ()):
        self._subscribers: list[Subscriber] = list(subscribers)

    def subscribe(self, subscriber: Subscriber) -> None:
        """Add a subscriber after those already there."""
        self._subscribers.append(subscriber)

    def publish(self, event: Any) -> None:
        """Hand `event` to each subscriber in turn (an exception stops it there, except for an
        end-of-run event, which every subscriber gets before the first exception is raised)."""
        if not getattr(event, "to_every_subscriber", False):
            for subscriber in self._subscribers:
                subscriber(event)
            return
        failure: BaseException | None = None
        for subscriber in self._subscribers:
            try:
                subscriber(event)
            except Exception as exc:  # noqa: BLE001 - raised after the others had it
                failure = failure or exc
        if failure is not None:
            raise failure
