"""The emulated optical bench: source, sample, hemisphere, detector aperture and detector model."""
