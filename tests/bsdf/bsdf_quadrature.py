"""BSDF test helpers: sphere quadrature on an equal-area grid and a chi-square test."""

from __future__ import annotations

import numpy as np
from scipy import stats


def direction(theta: float, phi: float = 0.0) -> np.ndarray:
    """Unit vector at polar angle theta (from +z) and azimuth phi."""
    return np.array([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])


def sphere_grid(nz: int, nphi: int, order: int, z_range=(-1.0, 1.0)):
    """Gauss-Legendre nodes of an equal-area (z, phi) grid of cells.

    Returns directions (nz, nphi, order*order, 3) and weights (order*order,) per cell in
    solid angle (all cells have the same area), so sum(w * f(dirs), -1) integrates f per cell.
    """
    x, w = np.polynomial.legendre.leggauss(order)
    z0, z1 = z_range
    dz = (z1 - z0) / nz
    dphi = 2 * np.pi / nphi
    zc = z0 + dz * (np.arange(nz)[:, None] + 0.5 + 0.5 * x[None, :])  # (nz, order)
    pc = dphi * (np.arange(nphi)[:, None] + 0.5 + 0.5 * x[None, :])  # (nphi, order)
    z = np.broadcast_to(zc[:, None, :, None], (nz, nphi, order, order))
    p = np.broadcast_to(pc[None, :, None, :], (nz, nphi, order, order))
    s = np.sqrt(np.maximum(1 - z * z, 0))
    dirs = np.stack([s * np.cos(p), s * np.sin(p), z], -1).reshape(nz, nphi, order * order, 3)
    weights = (0.25 * dz * dphi * w[:, None] * w[None, :]).reshape(-1)
    return dirs, weights


def integrate_sphere(f, nz=64, nphi=128, order=6, z_range=(-1.0, 1.0)) -> float:
    """Integral of f(directions) over the sphere (or a z band), by cellwise Gauss-Legendre."""
    dirs, w = sphere_grid(nz, nphi, order, z_range)
    return float(np.sum(f(dirs) * w))


def chi_square_pvalue(samples: np.ndarray, pdf, nz=20, nphi=40, order=8) -> tuple[float, float]:
    """p-value of the chi-square test of sample directions against the density pdf.

    Cells of an equal-area (z, phi) grid; expected counts from the pdf integrated per cell and
    scaled to the number of samples; cells expecting < 5 are pooled. Also returns the integral
    of pdf over the sphere (the fraction of samples that should be valid).
    """
    dirs, w = sphere_grid(nz, nphi, order)
    cell_mass = np.sum(pdf(dirs) * w, -1).reshape(-1)
    total = cell_mass.sum()
    z = np.clip(samples[:, 2], -1, np.nextafter(1, 0))
    phi = np.mod(np.arctan2(samples[:, 1], samples[:, 0]), 2 * np.pi)
    iz = np.minimum(((z + 1) / 2 * nz).astype(int), nz - 1)
    ip = np.minimum((phi / (2 * np.pi) * nphi).astype(int), nphi - 1)
    observed = np.bincount(iz * nphi + ip, minlength=nz * nphi).astype(float)
    expected = cell_mass / total * len(samples)
    small = expected < 5
    obs = np.append(observed[~small], observed[small].sum())
    exp = np.append(expected[~small], expected[small].sum())
    keep = exp > 0
    assert obs[~keep].sum() == 0, "samples fell where the pdf integrates to zero"
    chi2 = np.sum((obs[keep] - exp[keep]) ** 2 / exp[keep])
    return float(stats.chi2.sf(chi2, keep.sum() - 1)), float(total)
