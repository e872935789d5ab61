"""One instance of every family per interesting parameter set, shared by the families' tests."""

from model.bsdf import ABg, CoatedDiffuse, Lambert, OrenNayar, RayleighRice

MODELS = {
    "lambert": Lambert(0.7),
    "oren-nayar full": OrenNayar(0.8, 0.4),
    "oren-nayar qualitative": OrenNayar(0.8, 0.4, variant="qualitative"),
    "coated ggx": CoatedDiffuse(0.6, 0.25, 1.5),
    "coated beckmann correlated": CoatedDiffuse(0.9, 0.08, 1.6, distribution="beckmann",
                                                masking="correlated"),
    "abg g=2": ABg(2e-3, 1e-3, 2.0),
    "abg g=1.5": ABg(0.05, 0.02, 1.5),
    "abg g=0": ABg(0.2, 0.0, 0.0),
    "abg g<0": ABg(0.01, 0.5, -1.0),
    "rayleigh-rice glass": RayleighRice(1.0, 2.0, 2.0, wavelength_nm=632.8, eta=1.5),
    "rayleigh-rice aluminium": RayleighRice(2.0, 3.0, 3.0, wavelength_nm=632.8, eta=1.37, k=7.6),
    "rayleigh-rice wide psd": RayleighRice(0.5, 0.2, 1.5, wavelength_nm=1064.0, eta=0.2, k=6.9),
}
