"""What a fit is asked for: the candidates, the free parameters, the fitted subset and the model's
optional terms (multiple scattering, the two-scale diffraction settings), checked on creation."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from calibration.candidates import DISTRIBUTION_NAMES, FAMILIES, MASKINGS
from calibration.fit.model import DIFFRACTION_SAMPLES, Diffraction
from calibration.reduced import ReducedData
from gonio.errors import GonioError

ALPHA_BOUNDS = (1e-4, 4.0)
ETA_BOUNDS = (1.001, 4.0)
SCALE_BOUNDS = (1e-3, 1e3)
MS_WALKS_MAX = 1 << 22


class FitError(GonioError):
    """A fit failed, is ill-conditioned, or was asked of data that cannot support it."""


#: The fitted incidence by default (at_measured_incidence moves it where the data hold none).
NORMAL = (0.0,)


@dataclass(frozen=True)
class FitOptions:
    """What to fit: the candidate distributions and masking forms (the best is reported),
    which parameters are free, and which points form the fitted subset."""

    distributions: tuple[str, ...] = DISTRIBUTION_NAMES
    maskings: tuple[str, ...] = ("separable",)
    anisotropic: bool = False
    fit_eta: bool = False
    fit_scale: bool = False
    eta: float | None = None  # fixed (or starting) eta; None: the data's meta["eta"]
    k: float | None = None  # conductor extinction (fixed); None: meta["k"] if meta["kind"] is
    #                         "conductor", else a dielectric
    fit_incidence_deg: tuple[float, ...] | None = NORMAL  # None: fit every valid point
    incidence_tol_deg: float = 0.5
    aperture_half_angle_deg: float | None = None  # None: meta's, if any; 0: point model
    aperture_order: int | None = None  # radial nodes of the aperture rule; None: from the lobe
    beam_divergence_deg: float | None = None  # half-angle; None: meta's, if any; 0: none
    multiple_scattering: bool = False  # add the random walk's orders >= 2 to the model
    ms_walks: int = 1 << 17  # walks per incidence and table alpha (the refit: x MS_CENTRE_WALKS)
    ms_seed: int = 0
    ms_slope_only: bool = False  # a fit for the model's slope (the reduction's angle terms):
    #   no refit of its term at the result, predictions' term walked forward (per point)
    diffraction: bool = False  # the two-scale model (Holzschuch-Pacanowski) around the trial one
    rms_height_nm: float | None = None  # nano-roughness of the K-correlation PSD (held fixed)
    correlation_length_um: float | None = None
    psd_exponent: float = 2.0
    wavelength_nm: float | None = None  # None: the data's meta["wavelength_nm"]
    diffraction_samples: int = DIFFRACTION_SAMPLES
    families: tuple[str, ...] | None = None  # the families compared (calibration.fit.select);
    #                                          None: those the data's sample kind allows

    def __post_init__(self) -> None:
        if self.diffraction:
            _check_diffraction_options(self)
        if isinstance(self.ms_walks, bool) or not isinstance(self.ms_walks, int) \
                or not 2 <= self.ms_walks <= MS_WALKS_MAX:
            raise FitError(f"fit: ms_walks must be an integer in [2, {MS_WALKS_MAX}], "
                           f"got {self.ms_walks!r}")
        if self.multiple_scattering and self.anisotropic:
            raise FitError("fit: multiple_scattering is tabulated against one alpha; it cannot "
                           "be combined with anisotropic")
        for name, given, known in (("distribution", self.distributions, DISTRIBUTION_NAMES),
                                   ("masking", self.maskings, MASKINGS)):
            if not given:
                raise FitError(f"fit: at least one {name} is needed")
            for value in given:
                if value not in known:
                    raise FitError(f"fit: unknown {name} {value!r}; known: {', '.join(known)}")
        for value in self.families or ():
            if value not in FAMILIES:
                raise FitError(f"fit: unknown family {value!r}; known: {', '.join(FAMILIES)}")
        if self.families is not None and not self.families:
            raise FitError("fit: at least one family is needed")
        if self.eta is not None and not ETA_BOUNDS[0] <= self.eta <= ETA_BOUNDS[1]:
            raise FitError(f"fit: eta must be in [{ETA_BOUNDS[0]}, {ETA_BOUNDS[1]}], "
                           f"got {self.eta!r}")


def _check_diffraction_options(options: FitOptions) -> None:
    """Raise FitError naming what a diffraction fit lacks or cannot combine with."""
    missing = [name for name in ("rms_height_nm", "correlation_length_um")
               if getattr(options, name) is None]
    if missing:
        raise FitError(f"fit: diffraction needs the nano-roughness {' and '.join(missing)} "
                       "(--rms-height-nm and --correlation-length-um; an all-emulated "
                       "run's [sim.sample] gives them)")
    for name in ("rms_height_nm", "correlation_length_um", "wavelength_nm"):
        value = getattr(options, name)
        if value is not None and not (math.isfinite(value) and value > 0):
            raise FitError(f"fit: {name} must be positive and finite, got {value!r}")
    if not (math.isfinite(options.psd_exponent) and options.psd_exponent > 1):
        raise FitError(f"fit: psd_exponent must be finite and > 1, got {options.psd_exponent!r}")
    samples = options.diffraction_samples
    if isinstance(samples, bool) or not isinstance(samples, int) or samples < 2 or samples % 2:
        raise FitError(f"fit: diffraction_samples must be an even integer >= 2, got {samples!r}")


def diffraction_settings(data: ReducedData, options: FitOptions) -> Diffraction | None:
    """The fit's diffraction term from the options and the data's wavelength; None when off."""
    if not options.diffraction:
        return None
    wavelength = options.wavelength_nm
    if wavelength is None:
        wavelength = data.meta.get("wavelength_nm")
    if wavelength is None:
        raise FitError("fit: diffraction needs the wavelength; the data carry no "
                       "meta['wavelength_nm'] and none was given")
    return Diffraction(float(options.rms_height_nm), float(options.correlation_length_um),
                       float(options.psd_exponent), float(wavelength),
                       options.diffraction_samples)


def walk_settings(options: FitOptions) -> tuple[int | None, int]:
    """(walks, seed) of the multiple-scattering term; walks None when it is off."""
    return (options.ms_walks if options.multiple_scattering else None), options.ms_seed


def fit_subset_mask(data: ReducedData, options: FitOptions) -> np.ndarray:
    """Which points the fit uses: valid, finite, positive sigma, at a chosen incidence."""
    usable = (data.valid & np.isfinite(data.bsdf) & np.isfinite(data.sigma)
              & (data.sigma > 0))
    if options.fit_incidence_deg is None:
        return usable
    theta_i = data.theta_i_deg
    near = np.zeros(len(theta_i), bool)
    for angle in options.fit_incidence_deg:
        near |= np.abs(theta_i - abs(angle)) <= options.incidence_tol_deg
    return usable & near


def at_measured_incidence(options: FitOptions, data: ReducedData) -> FitOptions:
    """The options, with a fit at the default normal incidence moved to the lowest incidence
    the data hold usable points at when they hold none at 0 deg (a plan that starts at 10 deg,
    a table of one incidence); any other choice of incidences as given."""
    if options.fit_incidence_deg != NORMAL or fit_subset_mask(data, options).any():
        return options
    usable = fit_subset_mask(data, replace(options, fit_incidence_deg=None))
    if not usable.any():
        return options
    lowest = float(np.min(np.abs(data.theta_i_deg[usable])))
    return replace(options, fit_incidence_deg=(round(lowest, 6),))


def describe_subset(options: FitOptions) -> str:
    """The fitted incidences as the fit's errors name them."""
    if options.fit_incidence_deg is None:
        return "any angle"
    return ", ".join(f"{a:g}" for a in options.fit_incidence_deg) + " deg"
