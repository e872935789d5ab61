"""The suite as a composition root: the emulator's truth handed to calibration as the command
line hands it (gonio_cli.emulator_truth), and the suite's own cache of walked
multiple-scattering tables (plane_store) under the checkout's .pytest_cache unless
GONIO_CACHE_DIR is set, so the tests neither read nor fill a user's ~/.cache/gonio, and the
slow tests, run after the main suite, read what it walked."""

import os
from pathlib import Path

from gonio_cli import emulator_truth

os.environ.setdefault("GONIO_CACHE_DIR",
                      str(Path(__file__).resolve().parents[1] / ".pytest_cache" / "gonio"))
emulator_truth.install()
