"""The emulated bench is ready before it serves: what the first reading where the stages stand
needs (its incidence's multiple-scattering tables) is built while the emulators start, so a
`gonio devices` against a fresh `gonio emulate` (or `--sim`, which starts the same way) never
waits on it past the meter's timeout. Counted on the sample's own table lobe: the first
reading builds no plane of it."""

from gonio_testkit import fast_config, serving, write_toml

from drivers.pm100 import Pm100
from sim.bench.sample import higher_order_lobe

ALPHA = 0.3217  # a roughness no other test's bench has: its tables start unbuilt here
WALKS = 1024  # cheap tables
ETA = 1.51


def test_the_first_reading_where_the_stages_stand_builds_no_table(tmp_path):
    cfg = fast_config()  # the stages power up at sample 0 deg (normal incidence), arm 6 deg
    cfg["sim"]["sample"] = {"kind": "hemisphere", "eta": ETA, "distribution": "ggx",
                            "alpha": ALPHA, "ms_walks": WALKS}
    lobe = higher_order_lobe("hemisphere", "ggx", ALPHA, ETA, 0.0, WALKS, cfg["sim"]["seed"])
    with serving(write_toml(tmp_path / "bench.toml", cfg)) as (endpoints, bench):
        built = lobe.planes_built
        assert built > 0  # the lobe is the bench's, its multiple scattering on
        esp = bench.emulators["esp"]
        assert [esp.axes[axis].motion.position() for axis in (1, 2)] == [0.0, 6.0]
        with Pm100(port=endpoints["pm100"][1], name="pm100", timeout_s=30.0) as meter:
            assert meter.read().power_w > 0.0
        assert lobe.planes_built == built
