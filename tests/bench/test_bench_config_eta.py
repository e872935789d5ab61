"""The sample's index in [sim.sample]: an index far below any material's is one clear
SimConfigError (it used to pass and overflow the bench's refraction at start-up)."""

import pytest

from sim.bench.config import ETA_RANGE, build_bench
from sim.devices.photodiode import SimConfigError


@pytest.mark.parametrize("eta", [9.8e-248, 0.0, 0.009, 10.5])
def test_eta_outside_the_range_is_refused(eta):
    refused = r"\[sim.sample\] eta: must be a number >= 0.01 and <= 10, got "
    with pytest.raises(SimConfigError, match=refused):
        build_bench({"sample": {"eta": eta}})


@pytest.mark.parametrize("eta", ETA_RANGE)
def test_eta_at_the_range_ends_warms_up(eta):
    build_bench({"sample": {"eta": eta}}).warm_up()
