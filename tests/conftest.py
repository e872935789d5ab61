"""The suite as a composition root: the emulator's truth handed to calibration as the command
line hands it (gonio_cli.emulator_truth), and the suite's own cache of walked
multiple-scattering tables (plane_store) under the checkout's .pytest_cache unless
GONIO_CACHE_DIR is set, so the tests neither read nor fill a user's ~/.cache/gonio (but for
the conformance suite's build of libbsdf, tests/conformance/libbsdf_reader.py), and the
slow tests, run after the main suite, read what it walked; and its own lock directory for
ports held by name (a VISA resource, a Modbus TCP server: drivers.port_lock) unless
GONIO_LOCK_DIR is set, so that two copies of the suite running side by side, which name the
same fake USB meter, never refuse each other."""

import os
from pathlib import Path

from gonio_cli import emulator_truth

CHECKOUT = Path(__file__).resolve().parents[1]
os.environ.setdefault("GONIO_CACHE_DIR", str(CHECKOUT / ".pytest_cache" / "gonio"))
os.environ.setdefault("GONIO_LOCK_DIR", str(CHECKOUT / ".pytest_cache" / "gonio-locks"))
Path(os.environ["GONIO_LOCK_DIR"]).mkdir(parents=True, exist_ok=True)
emulator_truth.install()
