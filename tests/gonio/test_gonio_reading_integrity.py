"""Every recorded reading belongs to its recorded position, even when device replies come late.

The emulated bench (ESP stages and PM100 over real ptys) answers some replies later than the
drivers' timeouts (a loaded machine, a slow bench integral), so queries time out and are
retried while their first replies are still on the way. A late reply must never be taken as
the answer to a later query: each sample reading is checked against the bench's true power
at the stage positions recorded with it.
"""

import random
import time

import numpy as np
import pytest
from gonio_testkit import fast_config

from gonio.config import parse_config
from gonio.engine import Engine
from gonio.instrument import build_instrument
from gonio.plan import build_schedule, parse_plan
from gonio.simulate import simulation
from gonio.store import RunWriter, open_run
from sim.bench import build_bench
from sim.devices.faults import FaultInjector

TIMEOUT_S = {"esp": 0.1, "pm100": 0.2}
# many short moves, no dwell: a reading follows its move as closely as the engine allows
PLAN = {"name": "late-replies", "averaging": 4, "dwell_s": 0.0, "grid": [
    {"side": ["reflection", "transmission"], "theta_i_deg": [0.0, 20.0],
     "theta_o_deg": {"start": -70.0, "stop": 70.0, "step": 10.0}, "skip_forbidden": True}]}


class LateReplies(FaultInjector):
    """Sends a seeded share of the replies that carry a measurement (a PM100 reading, an
    ESP position or motion-done flag: `fields` of them, split at `sep`) between 1.1 and 1.9
    driver timeouts late. The reply itself is made on time: a PM100 reading is of the light
    when the query arrived."""

    def __init__(self, timeout_s: float, share: float, sep: bytes, fields: int, seed: int):
        super().__init__()
        self.timeout_s, self.share, self.sep, self.fields = timeout_s, share, sep, fields
        self._draw = random.Random(seed)
        self.late = 0

    def reply(self, data: bytes, keep_tail: int = 0, crc_bytes: int = 0) -> bytes | None:
        if data.count(self.sep) + 1 == self.fields and self._draw.random() < self.share:
            self.late += 1
            time.sleep(self.timeout_s * self._draw.uniform(1.1, 1.9))
        return super().reply(data, keep_tail, crc_bytes)


# READ?;:SENS:POW:RANG?;:SYST:ERR? answers 3 fields; nTP?;TB? and nMD?;TB? answer 4
MEASUREMENTS = {"pm100": (b";", 3), "esp": (b",", 4)}


@pytest.mark.parametrize("late", [
    pytest.param({"pm100": 0.25}, id="pm100-late"),
    pytest.param({"esp": 0.05, "pm100": 0.25}, id="both-late"),
])
def test_late_replies_never_answer_a_later_query(tmp_path, late):
    raw = fast_config("sim-serial", time_scale=200.0,
                      **{dev: {"timeout_s": t} for dev, t in TIMEOUT_S.items()})
    # single scattering: no lobe table to build at a new incidence (a first reading that
    # takes seconds would outlast every retry of these short timeouts)
    raw["sim"]["sample"]["multiple_scattering"] = False
    cfg = parse_config(raw)
    plan = parse_plan(PLAN)
    sched = build_schedule(plan, cfg)
    with simulation(cfg) as sim, build_instrument(sim.config, sim.time_scale) as inst:
        injectors = {dev: LateReplies(TIMEOUT_S[dev], share, *MEASUREMENTS[dev], seed=7)
                     for dev, share in late.items()}
        for dev, injector in injectors.items():
            sim.bench.emulators[dev].server.faults = injector
        writer = RunWriter.create(tmp_path, plan.name, None, None, PLAN, cfg.raw, {})
        writer.start_session()
        try:
            outcome = Engine(inst, plan, sched.readings, writer).run()
        finally:
            writer.close()
    assert outcome.status == "completed", outcome.reason
    assert all(injector.late >= 5 for injector in injectors.values())  # it did happen

    rows = open_run(writer.path).readings()
    np.testing.assert_array_equal(rows["index"], np.arange(len(sched.readings)))
    for role in ("sample", "arm"):
        np.testing.assert_allclose(rows[f"{role}_deg"], sched.readings[f"{role}_deg"],
                                   atol=0.01)
    bench = build_bench(cfg.raw["sim"])
    sample = rows[rows["kind"] == "sample"]
    truth = np.array([bench.scattered_fraction({"sample": s, "arm": a}) for s, a in
                      zip(sample["sample_deg"], sample["arm_deg"], strict=True)])
    truth_w = truth * cfg.raw["sim"]["source"]["power_w"]
    # noise, dark offset and quantisation stay well inside 2 % for these powers (>= 4e-9 W,
    # on ranges chosen for them); a neighbouring point's light is off by far more
    seen = truth_w > 4e-9
    assert seen.sum() >= 20
    ratio = sample["power_w"][seen] / truth_w[seen]
    wrong = np.abs(ratio - 1.0) > 0.02
    assert not wrong.any(), [(int(i), round(float(r), 3)) for i, r in
                             zip(sample["index"][seen][wrong], ratio[wrong], strict=True)]
