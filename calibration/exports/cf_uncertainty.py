"""The reduced NetCDF's uncertainty as machines read it: the BSDF names its standard and expanded
uncertainty in `uncertainty_variables` (CF's draft uncertainty chapter, cf-conventions pull
request 661), each a Gaussian coverage interval with its `coverage_probability`; and its error
structure the obsarray way (`unc_comps`, `err_corr_1_*`), which punpy propagates: the points'
independent errors (`random` along `point`) and the errors they share (ReducedData.shared_rel:
one standard uncertainty and an explicit correlation matrix between points), so that
u_random^2 + u_shared^2 = u^2 and the covariance is gonio's own, diag(u_random^2) + S S^T."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from calibration.reduced import ReducedData

RANDOM = "bsdf_random_uncertainty"
SHARED = "bsdf_shared_uncertainty"
CORRELATION = "bsdf_shared_error_correlation"
#: The correlation matrix's second dimension: `point` again (CF wants a variable's dimensions
#: distinct).
OTHER_POINT = "other_point"
GAUSSIAN = "gaussian"


def coverage_probability(k: float) -> float:
    """The probability that a Gaussian error lies within k standard deviations."""
    return math.erf(k / math.sqrt(2.0))


def shared_errors(data: ReducedData) -> np.ndarray:
    """(N, k) absolute errors the points share (the values carry shared_errors @ z, z ~ N(0, I));
    0 where a value is not finite."""
    scale = np.where(np.isfinite(data.bsdf), np.abs(data.bsdf), 0.0)
    return scale[:, None] * data.shared_rel


def shared_correlation(errors: np.ndarray) -> np.ndarray:
    """The correlation matrix between points of the shared errors S: S S^T / (u_i u_j), with
    u = |S_i|; 1 on the diagonal, 0 off it for a point that shares nothing."""
    u = np.linalg.norm(errors, axis=1)
    unit = np.divide(errors, u[:, None], out=np.zeros_like(errors), where=u[:, None] > 0)
    corr = unit @ unit.T
    np.fill_diagonal(corr, 1.0)
    return corr


def mark_interval(var: Any, k: float) -> None:
    """A standard (k = 1) or expanded uncertainty variable as a Gaussian coverage interval."""
    var.probability_distribution = GAUSSIAN
    var.coverage_factor = float(k)
    var.coverage_probability = coverage_probability(k)


def _component(ds: Any, name: str, values: np.ndarray, long_name: str, form: str,
               params: list[str]) -> None:
    """An obsarray uncertainty component along `point`: its values and error-correlation form."""
    var = ds.createVariable(name, "f8", ("point",))
    var[:] = values
    var.long_name = long_name
    var.units = "sr-1"
    var.pdf_shape = GAUSSIAN
    var.err_corr_1_dim = "point"
    var.err_corr_1_form = form
    var.err_corr_1_params = params
    var.err_corr_1_units = []


def write_error_structure(ds: Any, data: ReducedData, bsdf_name: str) -> list[str]:
    """The random and shared components of the BSDF and the shared errors' correlation matrix,
    named on the data variable (`unc_comps`); the names written, for `ancillary_variables`."""
    errors = shared_errors(data)
    _component(ds, RANDOM, data.sigma_own, "standard uncertainty of bsdf from the errors "
               "each point has alone (independent between points)", "random", [])
    names = [RANDOM]
    if errors.shape[1]:
        _component(ds, SHARED, np.linalg.norm(errors, axis=1), "standard uncertainty of bsdf "
                   "from the errors points share (correlated as " + CORRELATION + " says)",
                   "err_corr_matrix", [CORRELATION])
        ds.createDimension(OTHER_POINT, len(data.bsdf))
        corr = ds.createVariable(CORRELATION, "f8", ("point", OTHER_POINT), zlib=True)
        corr[:] = shared_correlation(errors)
        corr.long_name = "correlation coefficient between points of the shared errors of bsdf"
        corr.units = "1"
        names += [SHARED, CORRELATION]
    ds[bsdf_name].unc_comps = [n for n in names if n != CORRELATION]
    return names


def read_shared_rel(ds: Any, bsdf: np.ndarray) -> np.ndarray | None:
    """ReducedData.shared_rel recovered from a file write_error_structure wrote (relative
    factors whose product S S^T is the file's shared covariance); None without one."""
    if SHARED not in ds.variables or CORRELATION not in ds.variables:
        return None
    u = np.nan_to_num(np.asarray(ds[SHARED][:], dtype=np.float64))
    cov = np.asarray(ds[CORRELATION][:], dtype=np.float64) * np.outer(u, u)
    values, vectors = np.linalg.eigh(cov)
    keep = values > values.max(initial=0.0) * 1e-12
    factors = vectors[:, keep] * np.sqrt(values[keep])
    scale = np.abs(bsdf)
    ok = (scale > 0) & np.isfinite(scale)
    return np.divide(factors, scale[:, None], out=np.zeros_like(factors), where=ok[:, None])
