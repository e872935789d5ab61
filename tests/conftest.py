"""The suite's own cache of walked multiple-scattering tables (plane_store): under the
checkout's .pytest_cache unless GONIO_CACHE_DIR is set, so the tests neither read nor fill a
user's ~/.cache/gonio, and the slow tests, run after the main suite, read what it walked."""

import os
from pathlib import Path

os.environ.setdefault("GONIO_CACHE_DIR",
                      str(Path(__file__).resolve().parents[1] / ".pytest_cache" / "gonio"))
