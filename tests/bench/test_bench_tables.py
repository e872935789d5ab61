"""Bench.prepare builds exactly the multiple-scattering table planes a schedule's readings ask
for: the planes a lazy evaluation of the same readings builds, no more, and none is built when
the readings are then taken; the estimate counts those planes and times them."""

import tomllib
from pathlib import Path

from sim.bench import tables
from sim.bench.config import build_bench
from sim.bench.sample import higher_order_lobe

WALKS = 1024
ALPHA = 0.3297  # a roughness no other test's bench has: its tables start unbuilt here
CONFIG = Path(__file__).resolve().parents[2] / "examples" / "instruments" / "sim-serial.toml"
READINGS = [{"sample": sample, "arm": arm} for sample in (0.0, 35.0, 90.0)
            for arm in (20.0, 80.0, 150.0, 200.0, 250.0, 330.0)]


def serial_config() -> dict:
    """The serial example bench's config."""
    return tomllib.loads(CONFIG.read_text())


def bench():
    """A fresh bench (its sample's own models) of the ground glass of roughness ALPHA, with the
    real aperture rule and the config's alignment offsets."""
    cfg = serial_config()
    cfg["sim"]["alignment"] = {"sample_offset_deg": 0.01, "arm_offset_deg": -0.02}
    cfg["sim"]["sample"] = {"kind": "hemisphere", "eta": 1.51, "distribution": "ggx",
                            "alpha": ALPHA, "ms_walks": WALKS, "multiple_scattering": True}
    return build_bench(cfg["sim"], cfg["optics"])


def test_prepare_builds_what_the_readings_ask_for_and_no_more(monkeypatch, tmp_path):
    monkeypatch.setenv("GONIO_CACHE_DIR", str(tmp_path))
    higher_order_lobe.cache_clear()
    lazy = bench()
    for where in READINGS:
        lazy.power_w(where)
    (lobe,) = lazy.sample.table_lobes()
    asked = lobe._built.copy()
    assert asked.any() and not asked.all()

    higher_order_lobe.cache_clear()  # a new lobe, its planes in the store the lazy one filled
    estimate = tables.estimate(bench(), READINGS)
    assert estimate.planes == 0 and estimate.seconds == 0.0  # all in the store
    assert estimate.evaluate_s > 0.0  # what preparing a warm cache still spends
    higher_order_lobe.cache_clear()
    prepared = bench()
    report = prepared.prepare(READINGS)
    (fresh,) = prepared.sample.table_lobes()
    assert fresh is not lobe
    assert (fresh._built == asked).all()
    assert report.planes == report.read == int(asked.sum()) and report.walked == 0
    built = tables.built(prepared)
    for where in READINGS:
        prepared.power_w(where)
    assert tables.built(prepared) == built
    assert report.record()["in_readings"] == 0
    prepared.power_w({"sample": 60.0, "arm": 100.0})  # a reading the schedule did not foresee
    assert report.record()["in_readings"] == tables.built(prepared) - built > 0


def test_the_estimate_counts_the_planes_prepare_walks_and_times_them(monkeypatch, tmp_path):
    monkeypatch.setenv("GONIO_CACHE_DIR", str(tmp_path))
    higher_order_lobe.cache_clear()
    estimate = tables.estimate(bench(), READINGS)
    higher_order_lobe.cache_clear()
    walked = []
    report = bench().prepare(READINGS, lambda done, total: walked.append((done, total)))
    assert estimate.planes == report.walked == report.planes > 0 and estimate.walks == WALKS
    assert estimate.seconds > 0.0
    assert walked[0] == (0, report.walked) and walked[-1] == (report.walked, report.walked)


def test_a_bench_without_tables_prepares_nothing():
    cfg = serial_config()
    cfg["sim"]["sample"] = {"alpha": [0.2, 0.3], "ms_walks": WALKS}  # anisotropic: no tables
    anisotropic = build_bench(cfg["sim"], cfg["optics"])
    report = anisotropic.prepare(READINGS, lambda done, total: None)
    assert (report.planes, report.walked) == (0, 0)
    assert tables.estimate(anisotropic, READINGS).planes == 0
