"""The virtual world: BSDF model, optical bench and device emulators."""
