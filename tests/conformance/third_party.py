"""Where the conformance suite finds the third-party references it tests against (readers and
schemas kept unmodified outside the checkout): $GONIO_THIRD_PARTY, else
../shared/third_party beside the checkout."""

from __future__ import annotations

import os
from pathlib import Path

CHECKOUT = Path(__file__).resolve().parents[2]


def third_party(name: str) -> Path:
    """The folder of one reference (`libbsdf`, `bird-brdf-json-schema`); it may be absent."""
    root = os.environ.get("GONIO_THIRD_PARTY")
    return (Path(root) if root else CHECKOUT.parent / "shared" / "third_party") / name
