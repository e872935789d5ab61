"""The emulated bench's source dip and the devices' interlock windows: what they do, and one
error naming the field for a bad table."""

import pytest

from sim.bench.config import build_bench
from sim.devices.faults import FaultConfigError, FaultSpec, InterlockInput
from sim.devices.photodiode import SimConfigError


def test_a_dip_lowers_the_power_for_its_duration_only():
    source = build_bench({"source": {"power_w": 2e-3, "dip": {
        "start_s": 10.0, "duration_s": 5.0, "depth": 0.25}}}).source
    assert [source.power_at(t) for t in (9.99, 10.0, 14.99, 15.0)] == [2e-3, 1.5e-3, 1.5e-3, 2e-3]


@pytest.mark.parametrize("dip, named", [
    ({"start_s": 1.0, "duration_s": 1.0}, "[sim.source] dip must be a table"),
    ({"start_s": 1.0, "duration_s": 0.0, "depth": 0.5}, "[sim.source] dip.duration_s"),
    ({"start_s": 1.0, "duration_s": 1.0, "depth": 1.5}, "[sim.source] dip.depth"),
])
def test_a_bad_dip_is_one_error_naming_the_field(dip, named):
    with pytest.raises(SimConfigError, match=named.replace("[", r"\[").replace("]", r"\]")):
        build_bench({"source": {"dip": dip}})


def test_an_interlock_opens_once_for_its_window_even_between_polls():
    spec = FaultSpec.from_dict({"interlock": {"start_s": 1.0, "duration_s": 0.5}}, "esp")
    now = [0.0]
    contact = InterlockInput(spec.interlock, lambda: now[0])
    assert contact.poll() == (False, False)
    now[0] = 2.0  # opened and closed again since the last poll: the device still saw it
    assert contact.poll() == (True, False)
    assert contact.poll() == (False, False)
    with pytest.raises(FaultConfigError, match=r"\[sim\.faults\.esp\] interlock: must be"):
        FaultSpec.from_dict({"interlock": {"start_s": 1.0}}, "esp")
