"""The emulated bench is ready before it serves: what the first reading where the stages stand
needs (its incidence's multiple-scattering tables) is built while the emulators start, so a
`gonio devices` against a fresh `gonio emulate` (or `--sim`, which starts the same way) never
waits on it past the meter's timeout. Counted on the sample's own table lobe: the first
reading builds no plane of it, and the warm-up builds none that the readings at the stages'
incidence do not need (a scene computes only what it needs)."""

from gonio_testkit import fast_config, serving, write_toml

from drivers.pm100 import Pm100
from sim.bench.config import build_bench
from sim.bench.sample import higher_order_lobe

ALPHA = 0.3217  # a roughness no other test's bench has: its tables start unbuilt here
OTHER_ALPHA = 0.3219  # another, for a bench of its own
WALKS = 1024  # cheap tables
ETA = 1.51


def bench_config(alpha: float) -> tuple[dict, object]:
    """The serial bench's config with a multiple-scattering sample of roughness alpha, and
    that sample's table lobe."""
    cfg = fast_config()
    cfg["sim"]["sample"] = {"kind": "hemisphere", "eta": ETA, "distribution": "ggx",
                            "alpha": alpha, "ms_walks": WALKS}
    return cfg, higher_order_lobe("hemisphere", "ggx", alpha, ETA, 0.0, WALKS,
                                  cfg["sim"]["seed"])


def test_the_first_reading_where_the_stages_stand_builds_no_table(tmp_path):
    cfg, lobe = bench_config(ALPHA)  # the stages power up at sample 0 deg, arm 6 deg
    with serving(write_toml(tmp_path / "bench.toml", cfg)) as (endpoints, bench):
        built = lobe.planes_built
        assert built > 0  # the lobe is the bench's, its multiple scattering on
        esp = bench.emulators["esp"]
        assert [esp.axes[axis].motion.position() for axis in (1, 2)] == [0.0, 6.0]
        with Pm100(port=endpoints["pm100"][1], name="pm100", timeout_s=30.0) as meter:
            assert meter.read().power_w > 0.0
        assert lobe.planes_built == built


def test_the_warm_up_builds_only_what_readings_at_the_stages_incidence_need():
    cfg, lobe = bench_config(OTHER_ALPHA)
    bench = build_bench(cfg["sim"], cfg["optics"])
    offsets = bench.alignment
    at = {"sample": 0.0, "arm": 6.0, "azimuth": 0.0, "elevation": 0.0}  # power-up
    for arm in (6.0, 40.0, 150.0, 186.0, 220.0):  # at normal incidence: reflected, transmitted
        bench.scattered_fraction({**at, "sample": at["sample"] + offsets.sample_offset_deg,
                                  "arm": arm + offsets.arm_offset_deg})
    built = lobe.planes_built
    assert built > 0
    bench.warm_up(at)
    assert lobe.planes_built == built  # no other incidence's tables
