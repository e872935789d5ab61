"""What the Bluesky tests share: a small gonio plan (reflection and transmission, dark and beam
readings on fixed ranges) on the emulated serial bench, and documents checked against
event-model's schemas."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "gonio"))
from gonio_testkit import fast_config, write_plan  # noqa: E402

PLAN = {
    "name": "bluesky-small", "averaging": 1,
    "sample": {"id": "ground-glass", "kind": "hemisphere", "eta": 1.51, "lit_from": "air"},
    "grid": [{"side": "reflection", "theta_i_deg": [0.0, 30.0],
              "theta_o_deg": {"start": -60.0, "stop": 60.0, "step": 30.0},
              "skip_forbidden": True},
             {"side": "transmission", "theta_i_deg": [0.0],
              "theta_o_deg": {"start": -20.0, "stop": 20.0, "step": 20.0}}],
    "dark": {"every": 4, "range": 1e-8},
    "beam": {"every": 6, "range": 1e-3},
}


def small_plan(folder: Path) -> Path:
    """The plan and its instrument (instant motion), written into folder."""
    return write_plan(folder, PLAN, fast_config())


def validated(docs: list[tuple[str, dict[str, Any]]]) -> list[tuple[str, dict[str, Any]]]:
    """The documents, each checked against event-model's schema for its name."""
    import event_model

    for name, doc in docs:
        event_model.schema_validators[event_model.DocumentNames[name]].validate(doc)
    return docs
