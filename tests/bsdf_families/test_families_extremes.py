"""Extreme inputs give finite values: grazing, normal and exactly horizontal directions, albedo
0 and 1, Oren-Nayar sigma 0 to pi/2, coats of alpha 1e-4 to 4 and eta near 1, ABg's B from
1e-12 to 1e6 and g from -10 to 10, Rayleigh-Rice over its parameters' and settings' whole
ranges; f, pdf and sample weights are finite and non-negative."""

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from model.bsdf import ABg, CoatedDiffuse, Lambert, OrenNayar, RayleighRice
from model.bsdf.families.rayleigh_rice import ETA, WAVELENGTH, K

GRAZING = [0.0, 1e-12, 1e-6, 0.3, math.pi / 2 - 1e-9, math.pi / 2 - 1e-15, math.pi / 2]
thetas = st.one_of(st.sampled_from(GRAZING), st.floats(0.0, math.pi / 2))
phis = st.floats(0.0, 2 * math.pi)
unit = st.floats(0.0, 1.0, exclude_max=True)


def _direction(theta, phi):
    return np.array([math.sin(theta) * math.cos(phi), math.sin(theta) * math.sin(phi),
                     math.cos(theta)])


def _check(model, angles, u):
    wi, wo = _direction(*angles[:2]), _direction(*angles[2:])
    f, p = model.eval(wi, wo), model.pdf(wi, wo)
    assert np.isfinite(f) and f >= 0 and np.isfinite(p) and p >= 0
    wo_s, weight, pdf = model.sample(wi, np.array(u))
    assert np.all(np.isfinite(wo_s)) and np.isfinite(weight) and weight >= 0
    assert np.isfinite(pdf) and pdf >= 0


angle_sets = st.tuples(thetas, phis, thetas, phis)
uniforms = st.tuples(unit, unit, unit)


@settings(max_examples=150, deadline=None)
@given(angles=angle_sets, u=uniforms, rho=st.sampled_from([0.0, 0.5, 1.0]),
       sigma=st.floats(0.0, math.pi / 2), variant=st.sampled_from(["full", "qualitative"]))
def test_lambert_and_oren_nayar(angles, u, rho, sigma, variant):
    _check(Lambert(rho), angles, u)
    _check(OrenNayar(rho, sigma, variant), angles, u)


@settings(max_examples=150, deadline=None)
@given(angles=angle_sets, u=uniforms, a=st.floats(0.0, 1e6),
       b=st.sampled_from([0.0, 1e-12 * 1.01, 1e-6, 1e-3, 1.0, 1e6]),
       g=st.one_of(st.sampled_from([-10.0, -1.0, 0.0, 1e-6, 2.0, 10.0]), st.floats(-10, 10)))
def test_abg(angles, u, a, b, g):
    model = ABg(a, b if g != 0 else 0.0, g) if b > 0 or g == 0 else ABg(a, 1e-3, g)
    _check(model, angles, u)
    assert np.isfinite(model.total_integrated_scatter(_direction(*angles[:2])))


@settings(max_examples=25, deadline=None)
@given(angles=angle_sets, u=uniforms, rho=st.sampled_from([0.0, 1.0]),
       alpha=st.sampled_from([1e-4, 1e-2, 0.5, 4.0]), eta=st.sampled_from([1.0001, 1.5, 4.0]),
       distribution=st.sampled_from(["ggx", "beckmann"]),
       masking=st.sampled_from(["separable", "correlated"]))
def test_coated(angles, u, rho, alpha, eta, distribution, masking):
    model = CoatedDiffuse(rho, alpha, eta, distribution, masking)
    assert 0.0 <= model.table.mean < 1.0 and np.all(model.table.albedo <= 1.0)
    _check(model, angles, u)


def _edges_and_inside(p):
    """A parameter's bounds, its bounds' neighbours and anything between."""
    lo, hi = p.lower, p.upper
    return st.one_of(st.sampled_from([lo, hi, lo * 1.001 if lo > 0 else 1e-9, hi * 0.999]),
                     st.floats(lo, hi))


@settings(max_examples=150, deadline=None)
@given(angles=angle_sets, u=uniforms,
       values=st.tuples(*(_edges_and_inside(p) for p in RayleighRice.PARAMETERS)),
       wavelength=_edges_and_inside(WAVELENGTH), eta=_edges_and_inside(ETA),
       k=st.one_of(st.just(0.0), _edges_and_inside(K)))
def test_rayleigh_rice(angles, u, values, wavelength, eta, k):
    model = RayleighRice(*values, wavelength_nm=wavelength, eta=eta, k=k)
    _check(model, angles, u)
    wi = _direction(*angles[:2])
    for value in (model.specular_reflectance(wi), model.smooth_surface_tis(wi)):
        assert np.isfinite(value) and value >= 0
