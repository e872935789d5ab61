"""The virtual world: BSDF model, optical bench and device emulators."""

from sim.kernel_cache import drop_stale_kernels

drop_stale_kernels()  # before any kernel loads from numba's cache (sim.kernel_cache says why)
