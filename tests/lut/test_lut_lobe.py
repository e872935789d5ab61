"""The blur and direction tables against the model's lobes at spot points (quadrature of the
model's eval over light directions), the prefilter kernel's moments against sampling, and the
split-sum evaluator's sun (multiple importance sampling) against a quadrature of the disk."""

from __future__ import annotations

import math
import os

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.stats import qmc

from gonio_cli.main import main
from model.bsdf.distributions import make_distribution
from model.bsdf.vectors import unit
from model.lut import TableSpec, bake, load_table, validate
from model.lut.direction import lookup_direction, polar_angle, refraction_angle
from model.lut.lobe import LobeEstimator
from model.lut.model import ModelEstimator, view_direction
from model.lut.prefilter import BLUR_MAX, equivalent_alpha, kernel_spreads, normalisation
from model.lut.splitsum import Environment, brute_force, prefiltered
from model.optics.quadrature import cap_rule, orthonormal_basis

U = qmc.Sobol(d=3, scramble=True, seed=21).random(2**13)
U_SUN = qmc.Sobol(d=2, scramble=True, seed=22).random(2**11)
ENV = Environment()
#: Far hemisphere as one cap about -N (Gauss-Legendre in the polar angle, trapezoid in phi).
FAR_NODES, FAR_WEIGHTS = cap_rule(np.array([0.0, 0.0, -1.0]), 0.5 * math.pi, 160)


def lobe_by_quadrature(mu: float, alpha: float, eta: float) -> tuple[float, float, float]:
    """(blur_alpha, residual, offset) from moments of f_t(l, v) |cos l| over l by quadrature of
    the model's eval (the renderer's integrand, not the estimator's sample())."""
    model = ModelEstimator("transmission").model(alpha, eta)
    w = model.eval(FAR_NODES, view_direction(mu)) * np.abs(FAR_NODES[:, 2]) * FAR_WEIGHTS
    first = (w @ FAR_NODES) / w.sum()
    second = np.einsum("n,ni,nj->ij", w, FAR_NODES, FAR_NODES) / w.sum()
    mean_cos = np.linalg.norm(first)
    axis = first / mean_cos
    blur = float(equivalent_alpha(1.0 - mean_cos))
    spread = 1.0 - axis @ second @ axis
    residual = spread / kernel_spreads(blur)[1] - 1.0
    offset = polar_angle(first) - refraction_angle(mu, eta)
    return blur, float(residual), float(offset)


@pytest.fixture(scope="module")
def lobe_tables():
    """4x4x4 blur and direction tables at 4096 samples per entry (about 0.5 s each)."""
    return {kind: bake(TableSpec(kind=kind, shape=(4, 4, 4), samples=4096, dtype="float32"))
            for kind in ("transmission-blur", "transmission-direction")}


# (N.V, alpha, eta) node indices: both sides of the interface, near-normal and grazing views.
SPOTS = [(3, 2, 3), (1, 3, 3), (0, 2, 2), (2, 3, 1), (3, 3, 0), (1, 2, 2)]


@pytest.mark.parametrize("spot", SPOTS)
def test_blur_and_direction_entries_match_the_models_lobe(lobe_tables, spot):
    blur_t, dir_t = lobe_tables["transmission-blur"], lobe_tables["transmission-direction"]
    mu, alpha, eta = (a.values()[k] for a, k in zip(blur_t.spec.axes, spot, strict=True))
    blur, residual, offset = lobe_by_quadrature(mu, alpha, eta)
    i, j, k = spot
    assert blur_t.data[k, j, i, 0] == pytest.approx(blur, rel=0.03)
    assert blur_t.data[k, j, i, 1] == pytest.approx(residual, abs=0.03)
    assert dir_t.data[k, j, i, 0] == pytest.approx(offset, abs=0.01)


def test_lookup_between_nodes_follows_the_lobe(lobe_tables):
    """A trilinear lookup in a smooth region (eta > 1, moderate roughness) is near the lobe."""
    mu, alpha, eta = 0.7, 0.5, 1.6
    blur, _, offset = lobe_by_quadrature(mu, alpha, eta)
    assert lobe_tables["transmission-blur"].lookup(mu, alpha, eta)[0] == pytest.approx(
        blur, rel=0.15)
    assert lobe_tables["transmission-direction"].lookup(mu, alpha, eta)[0] == pytest.approx(
        offset, abs=0.05)


def test_smooth_surface_refracts_ideally_and_eta_one_does_not_blur():
    spec = TableSpec(kind="transmission-blur", shape=(3, 2, 2), samples=256)
    est = LobeEstimator.for_spec(spec)
    params = np.array([[0.6, 0.0, 1.5], [0.6, 0.5, 1.0 + 1e-9]])
    out = est(params, U[:256], np.random.default_rng(0))
    assert out[0].tolist() == [0.0, 0.0]
    assert out[1, 0] < 1e-6  # eta = 1: every facet passes the light straight on


@pytest.mark.parametrize("alpha", [0.01, 0.2, 0.7, 2.0])
def test_kernel_spreads_equal_sampling_the_kernel(alpha):
    """1 - E_k[d.l] and 1 - E_k[(d.l)^2] by quadrature in u against GGX normal sampling
    about N."""
    u = qmc.Sobol(d=2, scramble=True, seed=23).random(2**16)  # the GGX tail converges slowly
    h = make_distribution("ggx", alpha).sample_normal(u[:, 0], u[:, 1])
    c = np.maximum(2.0 * h[:, 2] ** 2 - 1.0, 0.0)  # d.l for l = reflect(N, h)
    one_minus_c = 2.0 * (h[:, 0] ** 2 + h[:, 1] ** 2)
    sampled = [np.sum(c * one_minus_c * f) / np.sum(c) for f in (1.0, 1.0 + c)]
    assert kernel_spreads(alpha) == pytest.approx(sampled, rel=2e-3)
    assert normalisation(alpha) == pytest.approx(np.mean(c), rel=2e-3)


def test_kernel_closed_forms_and_inversion():
    assert kernel_spreads(1.0)[0] == pytest.approx(1.0 / 3.0, rel=1e-12)
    assert kernel_spreads(0.0) == pytest.approx([0.0, 0.0], abs=1e-290)
    # small kernels keep their digits: 1 - E_k[d.l] grows like alpha^2 ln(1 / alpha)
    ratio = kernel_spreads(1e-9)[0] / kernel_spreads(1e-8)[0]
    assert ratio == pytest.approx(1e-2 * math.log(1e9) / math.log(1e8), rel=0.01)
    alpha = np.array([1e-3, 0.05, 0.4, 1.0, 3.0])
    assert equivalent_alpha(kernel_spreads(alpha)[0]) == pytest.approx(alpha, rel=1e-4)


@pytest.mark.parametrize("alpha, offset", [(0.003, 0.0), (0.05, 0.01), (0.3, 0.2)])
def test_prefiltered_sun_equals_quadrature_over_the_disk(alpha, offset):
    """The prefilter's sun share (MIS of kernel and disk samples) against a cap quadrature
    of the normalised kernel over the disk."""
    d = unit(ENV.sun_direction + np.array([offset, 0.0, 0.0]))
    nodes, weights = cap_rule(ENV.sun_direction, math.radians(ENV.sun_radius), 24)
    e1, e2 = orthonormal_basis(d)
    local = unit(nodes + d) @ np.stack([e1, e2, d]).T
    kernel = make_distribution("ggx", alpha).D(local) * np.maximum(nodes @ d, 0.0) / 4.0
    exact = ENV.sun_radiance * np.sum(kernel * weights) / normalisation(alpha)
    dark = Environment(sun_radiance=0.0)
    sun = prefiltered(ENV, d, alpha, U[:, :2], U_SUN) - prefiltered(dark, d, alpha, U[:, :2],
                                                                    U_SUN)
    assert sun == pytest.approx(exact, rel=0.02, abs=1e-3)


@pytest.mark.parametrize("mu, alpha, eta", [(0.5, 0.1, 1.5), (0.9, 0.4, 0.7),
                                            (0.6, 0.02, 1.2)])
def test_brute_force_sun_equals_quadrature_over_the_disk(mu, alpha, eta):
    model = ModelEstimator("transmission").model(alpha, eta)
    nodes, weights = cap_rule(ENV.sun_direction, math.radians(ENV.sun_radius), 24)
    f = model.eval(np.broadcast_to(view_direction(mu), nodes.shape), nodes)
    exact = ENV.sun_radiance * np.sum(f * np.abs(nodes[:, 2]) * weights) / eta**2
    sun = (brute_force(ENV, mu, alpha, eta, U, U_SUN)
           - brute_force(Environment(sun_radiance=0.0), mu, alpha, eta, U, U_SUN))
    assert sun == pytest.approx(exact, rel=0.02)


def test_split_sum_is_exact_for_smooth_glass_and_a_uniform_sky():
    """Analytic limits: a nearly smooth surface sees the environment at the refraction
    direction, and a constant environment prefilters to itself."""
    mu, eta = 0.8, 1.5
    d = lookup_direction(mu, eta)
    T = ModelEstimator("transmission")(np.array([[mu, 1e-4, eta]]), U, None)[0, 0]
    assert brute_force(ENV, mu, 1e-4, eta, U, U_SUN) == pytest.approx(
        T * float(ENV.radiance(d)), rel=1e-3)
    assert prefiltered(Uniform(sun_radiance=0.0), d, 0.3, U[:, :2], U_SUN) == pytest.approx(
        1.0, rel=2e-3)


class Uniform(Environment):
    """Radiance 1 everywhere but the sun."""

    def base(self, l):
        return np.ones(l.shape[:-1])


def test_cli_bakes_validates_and_stores_the_lobe_kinds(tmp_path, capsys):
    out = tmp_path / "blur.npz"
    assert main(["lut", "--kind", "transmission-blur", "--size", "4x3x2", "--samples", "64",
                 "--dtype", "float32", "--validate", "--validate-entries", "8",
                 "--validate-points", "8", "--reference-samples", "256",
                 "--out", str(out)]) == 0
    table = load_table(out)
    assert table.spec.channels == ("blur_alpha", "residual") and table.data.shape == (2, 3, 4, 2)
    assert table.validation["entries_checked"] == 8
    assert "blur_alpha" in table.metadata()["definitions"]
    report = validate(bake(TableSpec(kind="transmission-direction", shape=(3, 3, 2),
                                     samples=256)), entries=6, points=6, reference_samples=512)
    assert report.entry_max < 0.1
    assert "baked transmission-blur 4x3x2" in capsys.readouterr().out


def test_multiple_scattering_is_refused_for_the_lobe_kinds():
    with pytest.raises(ValueError, match="single-scattering lobe"):
        TableSpec(kind="transmission-direction", multiple_scattering=True)


BLUR = LobeEstimator("transmission-blur")
DIRECTION = LobeEstimator("transmission-direction")


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(mu=st.one_of(st.sampled_from([0.0, 1e-300, 1e-12, 1e-6, 1.0]), st.floats(0, 1)),
       alpha=st.one_of(st.sampled_from([0.0, 1e-12, 1e-7, 1e-4, 1.0]), st.floats(0, 1)),
       eta=st.one_of(st.sampled_from([0.4, 1 - 1e-12, 1.0, 1 + 1e-12, 2.5]),
                     st.floats(0.4, 2.5)))
def test_extreme_inputs_give_finite_bounded_lobe_values(mu, alpha, eta):
    point = np.array([[mu, alpha, eta]])
    blur, residual = BLUR(point, U[:256], None)[0]
    (offset,) = DIRECTION(point, U[:256], None)[0]
    assert np.isfinite([blur, residual, offset]).all()
    assert 0.0 <= blur <= BLUR_MAX and residual >= -1.0
    assert -0.5 * math.pi <= offset <= 0.5 * math.pi


def test_refraction_follows_snell_and_grazes_under_total_internal_reflection():
    mu = np.array([1.0, 0.5, 0.1])
    theta = refraction_angle(mu, 1.5)
    assert np.sin(theta) == pytest.approx(np.sqrt(1 - mu**2) / 1.5, rel=1e-12)
    assert refraction_angle(0.3, 1 / 1.5) == 0.5 * math.pi  # below the critical N.V 0.745
    d = lookup_direction(0.5, 1.5, 0.1)
    assert polar_angle(d) == pytest.approx(refraction_angle(0.5, 1.5) + 0.1, rel=1e-12)
    assert np.linalg.norm(d) == pytest.approx(1.0) and d[2] < 0 < -d[0]


@pytest.mark.parametrize("kind", ["transmission-blur", "transmission-direction"])
def test_lobe_tables_round_trip_through_exr(tmp_path, kind):
    if not os.environ.get("CI"):  # CI installs gonio[exr] with the test extra: never skip there
        pytest.importorskip("OpenEXR", reason="the OpenEXR bindings are not installed "
                            "(pip install 'gonio[exr]')")
    table = bake(TableSpec(kind=kind, shape=(3, 2, 2), samples=64))
    back = load_table(table.save(tmp_path / "t.exr"))
    assert back.data.tobytes() == table.data.tobytes() and back.spec == table.spec
