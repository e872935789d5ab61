"""Take the live view's screenshot for the docs (docs/img/watch.png): the README's demo scan
(--sim) followed by `gonio watch` with the session's token, in headless Chromium, once about
two thirds of its readings are in and every panel has its emulator-truth curve.

Run by hand: PYTHONPATH=$PWD python tests/gonio/watch_screenshot.py [OUT.png]
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

sys.path[:0] = [str(Path(__file__).resolve().parent), str(Path(__file__).resolve().parents[1])]

from gonio_testkit import EXAMPLES, ROOT  # noqa: E402
from waiting import wait_until  # noqa: E402
from watch_testkit import chromium, page_counts, scanning, watching  # noqa: E402

from gonio.store import open_run  # noqa: E402

SHARE = 0.65  # of the planned readings stored when the picture is taken
CURVES = ("return [document.querySelectorAll('.bsdf-panel').length,"
          " new Set([...document.querySelectorAll('.bsdf-panel path[stroke=\"#c0392b\"]')]"
          ".map(p => p.closest('svg').id)).size]")


def main() -> None:
    """Scan, watch, wait, take the picture."""
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT / "docs" / "img" / "watch.png"
    out.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp, \
            scanning(EXAMPLES / "plans" / "demo.toml", Path(tmp) / "runs", "--time-scale", "6",
                     timeout=180) as scan, \
            watching(scan.run_dir, scan.token()) as url, chromium(1400, 1250) as driver:
        driver.get(url)
        planned = open_run(scan.run_dir).meta["planned"]

        def ready() -> bool:
            panels, with_curves = driver.execute_script(CURVES)
            return page_counts(driver)[0] >= SHARE * planned and 0 < panels == with_curves

        wait_until(ready, timeout_s=180, poll_s=0.2, what="the picture's moment")
        height = driver.execute_script("return document.documentElement.scrollHeight")
        driver.set_window_size(1400, height + 140)  # the whole page (the window's frame)
        driver.save_screenshot(str(out))
    print(out)


if __name__ == "__main__":
    main()
