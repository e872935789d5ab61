"""Physics of the families: reciprocity, directional albedo by hemisphere quadrature (Lambert
exactly rho; the coated model's white furnace; Oren-Nayar's known gain and loss; ABg's total
integrated scatter in closed form), and the parameters by name that a fit builds them from."""

import math

import numpy as np
import pytest
from bsdf_quadrature import direction, integrate_sphere
from disk_quadrature import integrate_about_specular
from families_cases import MODELS

from model.bsdf import ABg, CoatedDiffuse, Lambert, OrenNayar, make_family
from model.bsdf.families import FAMILY_NAMES, family_class


def albedo(model, theta_i, nz=64, nphi=64, order=6):
    """int f(wi, wo) cos_o dwo over the upper hemisphere, by cellwise Gauss-Legendre."""
    wi = direction(theta_i, 0.3)
    return integrate_sphere(lambda d: model.eval(wi, d) * d[..., 2], nz=nz, nphi=nphi,
                            order=order, z_range=(0.0, 1.0))


@pytest.mark.parametrize("name", sorted(MODELS))
def test_reciprocity(name):
    rng = np.random.default_rng(5)
    wi, wo = rng.normal(size=(2, 2000, 3))
    wi[:, 2], wo[:, 2] = np.abs(wi[:, 2]), np.abs(wo[:, 2])
    model = MODELS[name]
    np.testing.assert_allclose(model.eval(wi, wo), model.eval(wo, wi), rtol=1e-12, atol=0)


@pytest.mark.parametrize("theta_i", [0.0, 0.8, 1.5])
def test_lambert_albedo_is_exactly_rho(theta_i):
    assert albedo(Lambert(0.37), theta_i, nz=4, nphi=4, order=4) == pytest.approx(0.37, rel=1e-13)


@pytest.mark.parametrize("coat", [dict(alpha=0.3, eta=1.5),
                                  dict(alpha=0.6, eta=1.8, distribution="beckmann"),
                                  dict(alpha=0.15, eta=1.5, masking="correlated")])
@pytest.mark.parametrize("theta_i", [0.0, 0.7, 1.2, 1.5])
def test_coated_white_furnace(coat, theta_i):
    """A white base under any coat reflects everything: a(i) + (1 - a(i)) = 1, to the albedo
    table's interpolation error (docs/bsdf-families.md: < 2e-4) and the quadrature's."""
    assert albedo(CoatedDiffuse(1.0, **coat), theta_i, 96, 96) == pytest.approx(1.0, abs=3e-4)


@pytest.mark.parametrize("rho", [0.0, 0.5])
def test_coated_albedo_is_the_layers_plus_rho_times_the_rest(rho):
    model = CoatedDiffuse(rho, 0.3, 1.5)
    a = albedo(model.layer, 0.9, 96, 96)
    assert albedo(model, 0.9, 96, 96) == pytest.approx(a + rho * (1 - a), abs=3e-4)
    assert a == pytest.approx(model.table(math.cos(0.9)), abs=2e-4)


@pytest.mark.parametrize("sigma", [0.1, 0.3, 0.6, 1.0])
@pytest.mark.parametrize("theta_i", [0.0, 0.8, 1.3, 1.5])
def test_oren_nayar_known_energy(sigma, theta_i):
    """Neither variant conserves energy: the qualitative model loses up to 35 % of rho at
    sigma = 1 and gains up to 1 % at grazing incidence and small sigma; the full model's
    interreflection term gives some of the loss back, up to 3.5 % above rho at grazing
    incidence and sigma ~ 0.3 (docs/bsdf-families.md tabulates both)."""
    full = albedo(OrenNayar(1.0, sigma), theta_i)
    qualitative = albedo(OrenNayar(1.0, sigma, "qualitative"), theta_i)
    assert 0.6 < qualitative < 1.01
    assert qualitative < full < 1.035


@pytest.mark.parametrize("abg", [(2e-3, 1e-3, 2.0), (0.05, 0.02, 1.5), (0.2, 0.0, 0.0),
                                 (0.01, 0.5, -1.0), (1e-3, 1e-2, 3.0)])
@pytest.mark.parametrize("theta_i", [0.0, 0.5, 1.0])
def test_abg_total_integrated_scatter_matches_quadrature(abg, theta_i):
    model, wi = ABg(*abg), direction(theta_i, 0.3)
    tis = float(model.total_integrated_scatter(wi))
    total = integrate_about_specular(lambda wo: model.eval(wi, wo), wi)
    assert tis == pytest.approx(total, rel=1e-6)


def test_abg_normal_incidence_closed_forms():
    assert ABg(1e-3, 1e-3, 2.0).total_integrated_scatter(np.array([0.0, 0, 1])) == \
        pytest.approx(math.pi * 1e-3 * math.log1p(1e3), rel=1e-9)
    assert ABg(0.2, 0.0, 0.0).total_integrated_scatter(direction(0.7)) == \
        pytest.approx(0.2 * math.pi, rel=1e-12)


def test_every_family_is_registered_and_built_from_its_parameter_names():
    for name in FAMILY_NAMES:
        cls = family_class(name)
        assert cls.family == name
        model = next(m for m in MODELS.values() if type(m) is cls)
        again = make_family(name, model.parameters(), **model.settings())
        wi, wo = direction(0.4), direction(0.5, 3.0)
        assert again.eval(wi, wo) == model.eval(wi, wo)
        assert [p.name for p in cls.PARAMETERS] == list(model.parameters())


def test_bad_parameters_are_one_clear_error():
    with pytest.raises(ValueError, match=r"rho must be finite and in \[0.0, 1.0\]"):
        Lambert(1.2)
    with pytest.raises(ValueError, match="sigma must be a number"):
        OrenNayar(0.5, "rough")
    with pytest.raises(ValueError, match="variant must be one of"):
        OrenNayar(0.5, 0.2, variant="improved")
    with pytest.raises(ValueError, match="B must be > 1e-12 unless g = 0"):
        ABg(1e-3, 0.0, 2.0)
    with pytest.raises(ValueError, match="alpha must be finite"):
        CoatedDiffuse(0.5, float("nan"))
    with pytest.raises(ValueError, match=r"unknown \['alpha'\], missing \['sigma'\]"):
        make_family("oren-nayar", {"rho": 0.5, "alpha": 0.2})
    with pytest.raises(ValueError, match=r"takes settings \['variant'\], not \['masking'\]"):
        make_family("oren-nayar", {"rho": 0.5, "sigma": 0.2}, masking="correlated")
    with pytest.raises(ValueError, match="distribution must be one of"):
        CoatedDiffuse(0.5, 0.2, 1.5, distribution="phong")
    with pytest.raises(ValueError, match="family must be one of"):
        make_family("phong", {})
    with pytest.raises(ValueError, match="directions must have shape"):
        Lambert().eval(np.zeros(2), np.zeros(3))
    with pytest.raises(ValueError, match="u must have shape"):
        Lambert().sample(direction(0.1), np.zeros(2))
