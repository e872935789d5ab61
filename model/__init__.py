"""What light does: the BSDF model families, the instrument optics both benches and the fit
share (aperture quadrature, exit face, edge circles), and the lookup tables baked from them."""

from model.kernel_cache import drop_stale_kernels

drop_stale_kernels()  # before any kernel loads from numba's cache (model.kernel_cache says why)
