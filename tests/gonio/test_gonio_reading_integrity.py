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
from gonio_testkit import fast_config, run_engine

from gonio.config import parse_config
from gonio.instrument import build_instrument
from gonio.plan import build_schedule, parse_plan
from gonio.simulate import simulation
from gonio.store import RunWriter, open_run
from sim.bench import build_bench
from sim.devices.faults import FaultInjector

TIMEOUT_S = {"esp": 0.1, "pm100": 0.2, "photodiode": 0.2}
# many short moves, no dwell: a reading follows its move as closely as the engine allows
PLAN = {"name": "late-replies", "averaging": 4, "dwell_s": 0.0, "grid": [
    {"side": ["reflection", "transmission"], "theta_i_deg": [0.0, 20.0],
     "theta_o_deg": {"start": -70.0, "stop": 70.0, "step": 10.0}, "skip_forbidden": True}]}
# Replies that carry a measurement: a PM100 READ?;:SENS:POW:RANG?;:SYST:ERR? (3 answers), an
# ESP nTP?;TB? (4 fields) or nMD?;nTP?;TB? (5 fields), a Modbus RTU read of input registers
# (function 04).
MEASUREMENTS = {"pm100": lambda reply: reply.count(b";") == 2,
                "esp": lambda reply: reply.count(b",") in (3, 4),
                "photodiode": lambda reply: reply[1:2] == b"\x04"}


class LateReplies(FaultInjector):
    """Sends every round(1 / share)-th reply that carries a measurement between 1.1 and 1.9
    driver timeouts late (seeded delays): a fixed share, so how many come late does not
    depend on how many polls a loaded machine needs. The reply itself is made on time: a
    reading is of the light when the query arrived."""

    def __init__(self, device: str, share: float, seed: int):
        super().__init__()
        self.timeout_s, self.every = TIMEOUT_S[device], round(1.0 / share)
        self.measurement = MEASUREMENTS[device]
        self._draw = random.Random(seed)
        self.measurements = self.late = 0

    def reply(self, data: bytes, keep_tail: int = 0, crc_bytes: int = 0) -> bytes | None:
        if self.measurement(data):
            self.measurements += 1
            if self.measurements % self.every == 0:
                self.late += 1
                # the fault under test: late past the driver's timeout, which is real time
                time.sleep(self.timeout_s * self._draw.uniform(1.1, 1.9))
        return super().reply(data, keep_tail, crc_bytes)


@pytest.mark.parametrize("instrument, late", [
    pytest.param("sim-serial", {"pm100": 0.25}, id="pm100-late"),
    pytest.param("sim-serial", {"esp": 0.1, "pm100": 0.25}, id="esp-and-pm100-late"),
    pytest.param("sim-modbus", {"photodiode": 0.25}, id="modbus-rtu-detector-late"),
])
def test_late_replies_never_answer_a_later_query(tmp_path, instrument, late):
    raw = fast_config(instrument, time_scale=200.0, **{dev: {"timeout_s": t} for dev, t in
                                                      TIMEOUT_S.items() if dev in late})
    # single scattering: no lobe table to build at a new incidence (a first reading that
    # takes seconds would outlast every retry of these short timeouts)
    raw["sim"]["sample"]["multiple_scattering"] = False
    cfg = parse_config(raw)
    plan = parse_plan(PLAN)
    sched = build_schedule(plan, cfg)
    with simulation(cfg) as sim, build_instrument(sim.config, sim.time_scale) as inst:
        injectors = {dev: LateReplies(dev, share, seed=7) for dev, share in late.items()}
        for dev, injector in injectors.items():
            emulator = sim.bench.emulators[dev]
            (emulator.server if hasattr(emulator, "server") else emulator).faults = injector
        writer = RunWriter.create(tmp_path, plan.name, None, None, PLAN, cfg.raw, {})
        try:
            outcome = run_engine(inst, plan, sched.readings, writer)
        finally:
            writer.close()
    assert outcome.status == "completed", outcome.reason
    # it did happen (at least 5 late per device)
    assert all(injector.late >= 5 for injector in injectors.values()), \
        {dev: (injector.late, injector.measurements) for dev, injector in injectors.items()}
    if "pm100" in late:  # and the driver had to bring its replies back in step
        assert inst.detector.transport.resyncs >= 3

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
    # noise, quantisation and the dark offset (~5e-11 W) stay inside 2 % + 2e-10 W on the
    # ranges autorange picks here; a neighbouring point's light is off by far more
    assert (truth_w > 1e-8).sum() >= 10
    wrong = np.abs(sample["power_w"] - truth_w) > 0.02 * truth_w + 2e-10
    assert not wrong.any(), [(int(i), float(p), float(t)) for i, p, t in zip(
        sample["index"][wrong], sample["power_w"][wrong], truth_w[wrong], strict=True)]
