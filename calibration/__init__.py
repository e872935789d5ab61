"""Raw readings -> BSDF values -> model parameters; calibration files and exports."""
