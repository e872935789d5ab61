"""Parameters and shapes: one clear error per bad argument, broadcasting over leading dims."""

import numpy as np
import pytest

from model.bsdf import RoughConductor, RoughDielectric


@pytest.mark.parametrize("kwargs,field", [
    (dict(distribution="gauss"), "distribution"),
    (dict(alpha=0.0), "alpha"),
    (dict(alpha=float("nan")), "alpha"),
    (dict(alpha=(0.1, 0.2, 0.3)), "alpha"),
    (dict(alpha=(0.1, -0.2)), "alpha_y"),
    (dict(eta=0.0), "eta"),
    (dict(eta=float("inf")), "eta"),
    (dict(masking="vcavity"), "masking"),
    (dict(sampling="uniform"), "sampling"),
    (dict(lobes=()), "lobes"),
    (dict(lobes=("reflection", "diffuse")), "lobes"),
    (dict(distribution="phong", sampling="visible"), "sampling"),
    (dict(distribution="phong", alpha=(0.1, 0.2)), "phong"),
    (dict(backend="cuda"), "backend"),
])
def test_dielectric_bad_arguments_name_the_field(kwargs, field):
    with pytest.raises(ValueError, match=field):
        RoughDielectric(**kwargs)


@pytest.mark.parametrize("eta", ["gold", -1 + 2j, complex("nan")])
def test_conductor_bad_index_names_the_field(eta):
    with pytest.raises(ValueError, match="eta_complex"):
        RoughConductor("ggx", 0.2, eta)


def test_directions_shape_is_checked():
    with pytest.raises(ValueError, match=r"\(\.\.\., 3\)"):
        RoughDielectric().eval(np.zeros((4, 2)), np.zeros((4, 3)))
    with pytest.raises(ValueError, match="u must"):
        RoughDielectric().sample(np.array([0, 0, 1.0]), np.zeros((4, 2)))


@pytest.mark.parametrize("backend", ["numpy", None])
def test_broadcasting_over_leading_dimensions(backend):
    model = RoughDielectric("beckmann", 0.3, 1.51, backend=backend)
    rng = np.random.default_rng(0)
    wi = rng.normal(size=(5, 1, 3))
    wo = rng.normal(size=(4, 3))
    f = model.eval(wi, wo)
    assert f.shape == (5, 4)
    assert f[2, 3] == model.eval(wi[2, 0], wo[3])
    wo_s, weight, pdf = model.sample(wi, rng.random((5, 6, 3)))
    assert wo_s.shape == (5, 6, 3) and weight.shape == pdf.shape == (5, 6)


def test_multiple_scattering_needs_a_generator():
    model = RoughDielectric(multiple_scattering=True)
    with pytest.raises(ValueError, match="rng="):
        model.eval(np.array([0, 0, 1.0]), np.array([0, 0, 1.0]))
