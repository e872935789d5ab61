"""The focusing term (model.lut.focusing): Walter's eq. 17 with the view fixed against a
finite-difference Jacobian of the half-vector map, and the quoted expression against a
numeric derivative of the relation it differentiates."""

from __future__ import annotations

import numpy as np

from model.lut.focusing import (
    approximation_error,
    exact_jacobian,
    facet_cosine,
    quoted_derivative,
)


def half_vector(light: np.ndarray, view: np.ndarray, eta: float) -> np.ndarray:
    """The transmission half vector -(eta l + o), normalised (towards the view's side)."""
    h = -(eta * light + view)
    h = h / np.linalg.norm(h, axis=-1, keepdims=True)
    return np.where((h @ view)[..., None] < 0, -h, h)


def numeric_jacobian(x: float, eta: float, step: float = 1e-6) -> float:
    """|d omega_h / d omega_l| by central differences: the light refracted through the facet
    at angle x from the view, moved along two tangent directions, and the solid angles its
    half vectors and it span."""
    view = np.array([np.sin(x), 0.0, np.cos(x)])  # facet normal h = z
    c_l = facet_cosine(x, eta)
    light = np.array([-np.sin(x) / eta, 0.0, -c_l])
    e1 = np.cross(light, [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(light, e1)
    moved = [light + s * step * e for e in (e1, e2) for s in (1, -1)]
    h = [half_vector(m / np.linalg.norm(m), view, eta) for m in moved]
    dh1, dh2 = (h[0] - h[1]) / (2 * step), (h[2] - h[3]) / (2 * step)
    return float(np.linalg.norm(np.cross(dh1, dh2)))


def test_exact_jacobian_equals_the_finite_difference_jacobian():
    rng = np.random.default_rng(3)
    for _ in range(60):
        eta = float(np.exp(rng.uniform(np.log(0.4), np.log(2.5))))
        if abs(eta - 1) < 0.02:
            continue
        x = rng.uniform(0, 0.98 * (np.arcsin(eta) if eta < 1 else np.pi / 2))
        assert np.isclose(exact_jacobian(x, eta), numeric_jacobian(x, eta), rtol=1e-5)
    # normal incidence: isotropic, (d x / d theta)^2 = eta^2 / (eta - 1)^2
    assert np.isclose(exact_jacobian(0.0, 1.5), 1.5**2 / 0.5**2)


def test_quoted_expression_is_the_derivative_of_the_relation_it_quotes():
    """-o.l = cos x sqrt(1 - a^2 sin^2 x) - a cos^2 x + a (a = 1 / eta): the quoted expression
    is d(-o.l)/dx over sqrt(1 - (o.l)^2)."""
    def minus_ol(x, a):
        return np.cos(x) * np.sqrt(1 - a * a * np.sin(x) ** 2) - a * np.cos(x) ** 2 + a

    x, a, h = np.linspace(0.05, 0.6, 12), 1 / 1.5, 1e-6
    numeric = (minus_ol(x + h, a) - minus_ol(x - h, a)) / (2 * h)
    assert np.allclose(quoted_derivative(x, a), numeric / np.sqrt(1 - minus_ol(x, a) ** 2),
                       rtol=1e-6)


def test_the_quoted_approximation_is_reported_against_the_exact_one():
    report = approximation_error(np.array([0.5, 0.8, 1.2, 1.5, 2.5]), angles=64)
    assert report["points"] == 5 * 64
    low, high = report["exact_over_quoted"]
    assert report["max_relative_error"] > 0.5 and high / low > 2  # not even a constant factor
