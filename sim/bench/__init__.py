"""The emulated optical bench: source, sample, hemisphere, detector aperture and detector model.

`build_power_source(sim_config, positions)` is what the detector emulators plug in.
"""

from sim.bench.config import build_bench, build_power_source
from sim.bench.scene import Bench

__all__ = ["Bench", "build_bench", "build_power_source"]
