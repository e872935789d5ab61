"""The cabinet of emulated samples, [sim.samples.<id>]: the bench mounts the one the plan's
[sample] id names, else [sim.sample]; every table of it is checked, one SimConfigError naming
the table and the key."""

import pytest

from sim.bench.config import build_bench, mounted_sample
from sim.devices.photodiode import SimConfigError

SIM = {"sample": {"distribution": "ggx", "alpha": 0.394},
       "samples": {"smooth": {"distribution": "beckmann", "alpha": 0.023},
                   "slab": {"kind": "slab", "alpha": 0.1}}}


def described(sample_id: str, **more) -> dict:
    return {"id": sample_id, "kind": "hemisphere", "eta": 1.51, **more}


def test_the_plan_sample_id_mounts_its_cabinet_table():
    spec = build_bench(SIM, None, described("smooth")).sample.spec
    assert (spec.distribution, spec.alpha) == ("beckmann", (0.023, 0.023))
    # what the cabinet's table leaves out comes from the plan's [sample]
    assert spec.kind == "hemisphere" and spec.eta == 1.51
    slab = build_bench(SIM, None, described("slab", eta=1.7)).sample.spec
    assert (slab.kind, slab.eta, slab.alpha) == ("slab", 1.7, (0.1, 0.1))


def test_any_other_id_or_no_plan_mounts_sim_sample():
    for sample in (described("my-glass"), None):
        spec = build_bench(SIM, None, sample).sample.spec
        assert (spec.distribution, spec.alpha) == ("ggx", (0.394, 0.394))
    assert mounted_sample(SIM, described("smooth"))[0] == "sim.samples.smooth"
    assert mounted_sample(SIM, None)[0] == "sim.sample"


@pytest.mark.parametrize("samples, message", [
    ({"smooth": {"alfa": 0.02}}, r"\[sim.samples.smooth\]: unknown key 'alfa'; known: kind, "),
    ({"smooth": {"alpha": 9.0}}, r"\[sim.samples.smooth\] alpha: must be a number"),
    ({"smooth": 0.02}, r"\[sim.samples.smooth\]: must be a table, got 0.02"),
    ("smooth", r"\[sim.samples\]: must be a table of sample tables, got 'smooth'"),
])
def test_a_bad_cabinet_table_is_named_whichever_sample_is_mounted(samples, message):
    for sample in (described("smooth"), described("my-glass")):
        with pytest.raises(SimConfigError, match=message):
            build_bench({**SIM, "samples": samples}, None, sample)


def test_checks_across_keys_name_the_mounted_table():
    sim = {"samples": {"coated": {"kind": "slab", "lit_from": "hemisphere"}}}
    with pytest.raises(SimConfigError, match=r'\[sim.samples.coated\] lit_from: "hemisphere" '
                                             r'needs kind = "hemisphere"'):
        build_bench(sim, None, described("coated"))
