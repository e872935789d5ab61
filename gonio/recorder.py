"""The run store's subscriber: what the engine publishes, written into the run directory.

It subscribes first, so storing a reading is as durable as the writer makes it (written at
once, fsynced before the next line) and a disk that refuses ends the run as failed: the
StoreError propagates to the engine. meta.json follows the state: paused, suspended (each
suspension kept under `suspensions`), running again, and the end with the session record (or,
when the directory refuses it, why, for the scan to say).
"""

from __future__ import annotations

from typing import Any

from gonio.events import (
    Paused,
    ReadingStored,
    Resumed,
    RunStarted,
    Stopped,
    Stopping,
    Suspended,
)
from gonio.store import RunWriter, StoreError


class RunRecorder:
    """Subscribes a RunWriter to a scan's events."""

    def __init__(self, writer: RunWriter):
        self.writer = writer

    def __call__(self, event: Any) -> None:
        """Record one event (StoreError if the disk refuses)."""
        writer = self.writer
        if isinstance(event, ReadingStored):
            writer.append(event.record)
        elif isinstance(event, RunStarted):
            writer.start_session(**event.session)
        elif isinstance(event, Paused):
            writer.set_status("paused", event.reason)
        elif isinstance(event, Suspended):
            writer.meta.setdefault("suspensions", []).append(event.suspension.to_json())
            writer.set_status("suspended", event.suspension.reason)
        elif isinstance(event, Resumed):
            if event.suspension is not None:
                writer.meta["suspensions"][-1] = event.suspension.to_json()
            writer.set_status("running", "")
        elif isinstance(event, Stopping):
            writer.wait_stored()
        elif isinstance(event, Stopped):
            self._stopped(event)

    def _stopped(self, event: Stopped) -> None:
        meta = self.writer.meta
        if event.unstopped:
            meta["unstopped"] = event.unstopped
        if meta["sessions"]:
            meta["sessions"][-1].update(event.session)
        unrecorded = record_end(self.writer, event.status, event.reason)
        if unrecorded:
            event.unrecorded.append(unrecorded)


def record_end(writer: RunWriter, status: str, reason: str) -> str:
    """Record how the run ended in meta.json; "" once recorded, else why the directory
    refused it (the readings already stored stay as they are)."""
    try:
        writer.set_status(status, reason)
    except StoreError as exc:
        return str(exc)
    return ""
