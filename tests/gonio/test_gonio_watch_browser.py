"""The live view in a real browser (headless Chromium): while a `gonio scan --sim` runs, the
page's stored count and raw plot follow the store (within a poll), the reduced BSDF appears
with the emulator's truth once dark and beam readings allow it, and the page's pause, resume
and abort buttons act on the scan through its control channel."""

import json
from functools import partial
from urllib.parse import urlsplit

import pytest
from waiting import wait_until
from watch_testkit import (
    chromium,
    missing,
    open_page,
    page_clock,
    page_counts,
    plan_file,
    polls_since,
    scanning,
    watching,
)

from gonio.store import open_run

pytestmark = [pytest.mark.browser,
              pytest.mark.skipif(missing() is not None, reason=str(missing()))]

LAG_POLLS = 2  # how far the page may be behind the store: a poll under way, and the next


def reduced_points(driver) -> int:
    """Points drawn in the reduced-BSDF panels (0 until the run is reducible)."""
    return driver.execute_script(
        "return document.getElementById('reduction-state').dataset.state === 'reduced'"
        " ? document.querySelectorAll('.bsdf-panel .pt').length : 0")


def caught_up(driver, stored: int, mark_ms: float) -> tuple[int, int, int] | bool:
    """(the page's count, its raw points, its polls since mark_ms) once a poll since the mark
    has answered and the page shows `stored` readings; False until then."""
    polls, (page, points, _) = polls_since(driver, mark_ms), page_counts(driver)
    return polls >= 1 and min(page, points) >= stored and (page, points, polls)


def test_page_follows_the_store_while_the_scan_runs(tmp_path):
    with scanning(plan_file(tmp_path, 4.0), tmp_path / "runs") as scan, \
            watching(scan.run_dir) as url, chromium(1400, 1250) as driver:
        open_page(driver, url)
        seen = []
        while scan.proc.poll() is None:
            before, mark = scan.stored(), page_clock(driver)
            # the page polls in between and shows what was stored before
            page, points, polls = wait_until(partial(caught_up, driver, before, mark),
                                             what=f"{before} readings on the page", poll_s=0.05)
            after = scan.stored()
            assert polls <= LAG_POLLS and page <= after and points <= after, \
                (before, page, points, after, polls)
            seen.append(page)
            if len(seen) == 3:
                driver.save_screenshot(str(tmp_path / "watch.png"))
        assert len(set(seen)) >= 3 and seen == sorted(seen), seen  # it grew as stored
        planned = open_run(scan.run_dir).meta["planned"]
        assert wait_until(lambda: page_counts(driver) == (planned, planned, "completed"),
                          what="the completed run on the page")
        assert wait_until(lambda: reduced_points(driver), what="reduced points") == 20
        curves = driver.execute_script(
            "return document.querySelectorAll('.bsdf-panel path[stroke=\"#c0392b\"]').length")
        assert curves >= 3  # the emulator's truth in each panel
        legend = driver.find_element("id", "bsdf-legend").text
        assert "emulator truth (ggx alpha 0.394" in legend
        origin = f"http://{urlsplit(url).netloc}/"
        loaded = driver.execute_script(
            "return performance.getEntriesByType('resource').map(e => e.name)")
        assert loaded and all(name.startswith(origin) for name in loaded), loaded  # no CDN
        errors = [e for e in driver.get_log("browser") if e["level"] == "SEVERE"]
        assert errors == []
        assert driver.find_element("id", "pause").get_attribute("disabled")
        assert "--token" in driver.find_element("id", "pause").get_attribute("title")
    assert (tmp_path / "watch.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_pause_resume_and_abort_from_the_page(tmp_path):
    with scanning(plan_file(tmp_path, 4.0), tmp_path / "runs") as scan, \
            watching(scan.run_dir, wait_until(scan.token, what="the token line")) as url, \
            chromium() as driver:
        open_page(driver, url)
        pause = driver.find_element("id", "pause")
        wait_until(lambda: pause.is_enabled() and page_counts(driver)[0] >= 3,
                   what="a running scan with the pause button enabled")
        pause.click()
        wait_until(lambda: page_counts(driver)[2] == "paused", what="paused on the page")
        meta = json.loads((scan.run_dir / "meta.json").read_text())
        assert meta["status"] == "paused"
        held, mark = scan.stored(), page_clock(driver)
        wait_until(lambda: polls_since(driver, mark) >= LAG_POLLS, what="polls of the paused run",
                   poll_s=0.05)
        assert scan.stored() == held and page_counts(driver)[0] == held  # nothing measured
        driver.find_element("id", "resume").click()
        wait_until(lambda: scan.stored() > held + 1, what="the scan going on after resume")
        wait_until(lambda: page_counts(driver)[2] == "running", what="running on the page")
        driver.find_element("id", "abort").click()
        driver.switch_to.alert.accept()
        assert scan.proc.wait(timeout=30) == 130
        run = open_run(scan.run_dir)
        assert run.meta["status"] == "aborted"
        assert run.meta["reason"] == "aborted from the control channel"
        assert len(run) < run.meta["planned"]
        wait_until(lambda: page_counts(driver)[2] == "aborted", what="aborted on the page")
