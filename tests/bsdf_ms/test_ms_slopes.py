"""Smith slope distributions on the whole sphere: signed Lambda, projected area, visible normals."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from model.bsdf.distributions import WALKABLE, make_distribution
from model.bsdf.multiple_scattering.walk import walkable

CASES = [("ggx", 0.3), ("ggx", (1.0, 0.4)), ("beckmann", 0.3), ("beckmann", (0.5, 1.2))]


def direction(theta, phi=0.7):
    return np.array([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])


def hemisphere_grid(n=600):
    """Midpoint grid over the upper hemisphere in (cos theta, phi), with solid-angle weights."""
    z = (np.arange(n) + 0.5) / n
    phi = (np.arange(2 * n) + 0.5) / (2 * n) * 2 * np.pi
    zz, pp = np.meshgrid(z, phi, indexing="ij")
    r = np.sqrt(1 - zz * zz)
    m = np.stack([r * np.cos(pp), r * np.sin(pp), zz], axis=-1)
    return m, (1.0 / n) * (np.pi / n)


@pytest.mark.parametrize("name,alpha", CASES)
@pytest.mark.parametrize("theta", [0.2, 1.2, 1.5707, 1.9, 2.8])
def test_projected_area_is_the_integral_of_visible_cosines(name, alpha, theta):
    s = make_distribution(name, alpha)
    m, dw = hemisphere_grid()
    w = direction(theta)
    numeric = np.sum(np.maximum(m @ w, 0.0) * s.D(m)) * dw
    assert s.projected_area(w[None])[0] == pytest.approx(numeric, rel=2e-3, abs=1e-12)


@pytest.mark.parametrize("name,alpha", CASES)
def test_lambda_of_the_opposite_direction(name, alpha):
    s = make_distribution(name, alpha)
    w = np.array([direction(t, p) for t in np.linspace(0.01, 1.56, 20) for p in (0.0, 1.0, 2.5)])
    assert np.allclose(s.signed_lambda(-w), -1.0 - s.signed_lambda(w), rtol=1e-13, atol=1e-13)
    assert np.all(s.signed_lambda(w) >= 0.0)


@pytest.mark.parametrize("name", WALKABLE)
def test_lambda_is_finite_and_monotone_at_extremes(name):
    s = make_distribution(name, 0.5)
    theta = np.concatenate([[0.0, 1e-12, 1e-6], np.linspace(0.1, 1.5, 30),
                            [np.pi / 2 - 1e-6, np.pi / 2 - 1e-12]])
    w = np.stack([np.sin(theta), 0 * theta, np.cos(theta)], axis=-1)
    lam = s.signed_lambda(w)
    assert np.all(np.isfinite(lam)) and lam[0] == 0.0
    assert np.all(np.diff(lam) >= 0.0)
    horizontal = s.signed_lambda(np.array([[1.0, 0.0, 0.0]]))
    assert horizontal[0] == np.inf
    assert np.isfinite(s.projected_area(np.array([[1.0, 0.0, 0.0]]))[0])


@pytest.mark.parametrize("name,alpha", CASES)
@pytest.mark.parametrize("theta", [0.0, 0.4, 1.3, 1.75, 2.6])
def test_visible_normal_sampling_matches_its_density(name, alpha, theta):
    """Chi-square test of sampled normals against D_visible binned in (m_z, phi), w above or
    below the horizon or straight above (Beckmann's closed form there)."""
    s = make_distribution(name, alpha)
    w = direction(theta)
    rng = np.random.default_rng(11)
    n = 40000
    u = rng.random((2, n))
    m = s.sample_visible_sphere(np.broadcast_to(w, (n, 3)), u[0], u[1])
    assert np.allclose(np.linalg.norm(m, axis=-1), 1.0) and np.all(m[:, 2] >= 0.0)
    assert np.all(m @ w >= -1e-12)
    nz, nphi = 8, 8
    grid, dw = hemisphere_grid(400)
    dens = s.D_visible(np.broadcast_to(w, grid.shape), grid) * dw
    zb = np.minimum((grid[..., 2] * nz).astype(int), nz - 1)
    azimuth = np.mod(np.arctan2(grid[..., 1], grid[..., 0]), 2 * np.pi)
    pb = (azimuth / (2 * np.pi) * nphi).astype(int)
    expected = np.bincount((zb * nphi + pb).ravel(), dens.ravel(), nz * nphi)
    assert expected.sum() == pytest.approx(1.0, abs=0.01)
    zs = np.minimum((m[:, 2] * nz).astype(int), nz - 1)
    ps = np.minimum((np.mod(np.arctan2(m[:, 1], m[:, 0]), 2 * np.pi) / (2 * np.pi) * nphi)
                    .astype(int), nphi - 1)
    observed = np.bincount(zs * nphi + ps, minlength=nz * nphi)
    keep = expected * n > 20
    exp_counts = expected[keep] / expected[keep].sum() * observed[keep].sum()
    chi2 = np.sum((observed[keep] - exp_counts) ** 2 / exp_counts)
    assert observed[~keep].sum() <= max(30, 3 * expected[~keep].sum() * n)
    assert stats.chi2.sf(chi2, keep.sum() - 1) > 1e-4


def test_phong_and_array_alpha_are_refused():
    with pytest.raises(ValueError, match="beckmann' or 'ggx"):
        walkable(make_distribution("phong", 0.3))
    with pytest.raises(ValueError, match="scalar alpha"):
        walkable(make_distribution("ggx", np.array([0.1, 0.2])))


@settings(max_examples=150, deadline=None)
@given(name=st.sampled_from(WALKABLE),
       ax=st.floats(1e-4, 5.0), ay=st.floats(1e-4, 5.0),
       theta=st.floats(0.0, np.pi), phi=st.floats(0.0, 2 * np.pi),
       u1=st.floats(0.0, 1.0, exclude_max=True), u2=st.floats(0.0, 1.0, exclude_max=True))
def test_visible_normals_are_finite_unit_and_visible_for_any_input(name, ax, ay, theta, phi,
                                                                   u1, u2):
    s = make_distribution(name, (ax, ay))
    w = direction(theta, phi)[None]
    m = s.sample_visible_sphere(w, np.array([u1]), np.array([u2]))
    assert np.all(np.isfinite(m)) and np.isclose(np.linalg.norm(m), 1.0)
    assert m[0, 2] >= 0.0
    if s.projected_area(w)[0] > 1e-12:  # else nothing is visible: the walk never asks
        assert float(m[0] @ w[0]) >= -1e-9
    lam = s.signed_lambda(w)
    assert not np.isnan(lam[0]) and np.isfinite(s.projected_area(w)[0])
