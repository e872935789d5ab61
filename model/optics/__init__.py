"""The instrument's optics around the rough interface, shared by the emulated bench, reduction
and plots: cap quadrature and the aperture integral, the exit face, the integrand's edges."""
