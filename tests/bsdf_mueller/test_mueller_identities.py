"""Identities every Mueller BSDF must keep, from physics: M00 is the unpolarised BSDF, analyser
sums give it back, reciprocity's transpose rule, physical realizability (Cloude), one facet's
matrix equal to a tilted mirror's by Maxwell's boundary conditions, frames fixed to +z."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from maxwell_interface import interface_mueller

from model.bsdf import RoughConductor, RoughDielectric
from model.bsdf.mueller import stokes_frame
from model.bsdf.multiple_scattering import RandomWalkBSDF
from model.bsdf.vectors import unit

#: Reciprocity's sign: M(wo, wi) = Q M(wi, wo)^T Q (docs/bsdf.md derives it).
Q = np.diag([1.0, 1.0, -1.0, 1.0])
PAULI = np.array([[[1, 0], [0, 1]], [[1, 0], [0, -1]], [[0, 1], [1, 0]], [[0, -1j], [1j, 0]]])


def models():
    return [RoughDielectric("ggx", 0.4, 1.51), RoughDielectric("beckmann", 0.2, 1 / 1.33),
            RoughDielectric("ggx", (0.1, 0.5), 2.4, masking="correlated"),
            RoughDielectric("phong", 0.3, 1.51, sampling="walter"),
            RoughConductor("ggx", 0.3, 0.18 + 3.43j), RoughConductor("beckmann", 0.5, None),
            RoughConductor("ggx", (0.05, 0.3), 1.37 + 7.62j, masking="correlated")]


def random_pairs(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return unit(rng.normal(size=(n, 3))), unit(rng.normal(size=(n, 3)))


def linear_polariser(theta: float) -> np.ndarray:
    """Mueller matrix of an ideal linear polariser whose axis is theta from s toward p."""
    c, s = np.cos(2 * theta), np.sin(2 * theta)
    return 0.5 * np.array([[1, c, s, 0], [c, c * c, c * s, 0], [s, c * s, s * s, 0],
                           [0, 0, 0, 0]])


def coherency_eigenvalues(m: np.ndarray) -> np.ndarray:
    """Eigenvalues of Cloude's coherency matrix (1/4) sum M_ij sigma_i (x) conj(sigma_j):
    all >= 0 exactly when M is a sum of non-depolarising (Jones) Mueller matrices."""
    h = 0.25 * np.einsum("...ij,iab,jcd->...acbd", m, PAULI, PAULI.conj()).reshape(
        m.shape[:-2] + (4, 4))
    return np.linalg.eigvalsh(h)


@pytest.mark.parametrize("model", models(), ids=repr)
def test_m00_is_the_unpolarised_bsdf_and_analyser_sums_give_it(model):
    """Analysers at 0/45/90/135 deg after any input: the four readings sum to 2 (M S)_0;
    0 + 90 = 45 + 135 = (M S)_0; polarisers and analysers at the four angles: 4 f for
    unpolarised light, f the model's own unpolarised eval."""
    wi, wo = random_pairs(3000, 1)
    m = model.eval_mueller(wi, wo)
    f = model.eval(wi, wo)
    np.testing.assert_array_equal(m[:, 0, 0], f)
    angles = np.radians([0.0, 45.0, 90.0, 135.0])
    analysers = np.array([linear_polariser(a)[0] for a in angles])  # detector reads S0
    source = np.array([1.0, 0.3, -0.5, 0.6])  # a partly polarised input
    readings = np.einsum("aj,njk,k->na", analysers, m, source)
    out = m @ source
    np.testing.assert_allclose(readings.sum(-1), 2 * out[:, 0], rtol=1e-12, atol=1e-300)
    np.testing.assert_allclose(readings[:, 0] + readings[:, 2], out[:, 0], rtol=1e-12, atol=1e-300)
    np.testing.assert_allclose(readings[:, 1] + readings[:, 3], out[:, 0], rtol=1e-12, atol=1e-300)
    both = sum(analysers[a] @ m @ linear_polariser(p) @ [1.0, 0, 0, 0]
               for a in range(4) for p in angles)
    np.testing.assert_allclose(both, 4 * f, rtol=1e-12, atol=1e-300)


@pytest.mark.parametrize("model", models(), ids=repr)
def test_reciprocity_is_the_transpose_rule(model):
    """M(wo, wi) / eta_i^2 = Q M(wi, wo)^T Q / eta_o^2, Q = diag(1, 1, -1, 1): Lorentz
    reciprocity of the scattering dyadic with wo's and wi's frames swapped (s -> -s)."""
    wi, wo = random_pairs(3000, 2)
    eta = getattr(model, "eta", 1.0)
    eta_i = np.where(wi[:, 2] > 0, 1.0, eta)[:, None, None]
    eta_o = np.where(wo[:, 2] > 0, 1.0, eta)[:, None, None]
    forward = model.eval_mueller(wi, wo)
    backward = model.eval_mueller(wo, wi)
    scale = np.abs(forward).max(axis=(-1, -2), keepdims=True) / eta_o**2
    gap = np.abs(backward / eta_i**2 - Q @ forward.swapaxes(-1, -2) @ Q / eta_o**2)
    # 1e-11: the compiled unpolarised eval (M00) is reciprocal to 3e-12 on these pairs
    assert np.all(gap <= 1e-11 * scale + 1e-300), (gap / (scale + 1e-300)).max()
    live = (forward[:, 0, 0] > 1e-280) & (backward[:, 0, 0] > 1e-280)  # normal floats
    shape_f = forward[live] / forward[live, :1, :1]
    shape_b = backward[live] / backward[live, :1, :1]
    np.testing.assert_allclose(shape_b, Q @ shape_f.swapaxes(-1, -2) @ Q, rtol=0, atol=1e-12)


@pytest.mark.parametrize("model", models()[:5], ids=repr)
def test_each_pair_is_a_tilted_mirror_by_maxwell(model):
    """M / M00 at random pairs equals the Mueller matrix of a flat interface whose normal is the
    pair's half vector, solved from the boundary conditions and read in wi's and wo's frames:
    the facet's Fresnel matrix and both frame rotations, checked without s/p algebra."""
    n = getattr(model, "eta", None) or model.eta_complex
    wi, wo = random_pairs(120, 3)
    m = model.eval_mueller(wi, wo)
    checked = 0
    for a, b, mm in zip(wi, wo, m, strict=True):
        if mm[0, 0] == 0:
            continue
        index = n if a[2] > 0 else 1 / n
        transmitted = a[2] * b[2] < 0
        normal = unit(-(a + index * b)) if transmitted else unit(a + b)
        exact = interface_mueller(-a, normal, index, stokes_frame(-a), stokes_frame(b),
                                  transmitted)
        np.testing.assert_allclose(mm / mm[0, 0], exact / exact[0, 0], rtol=0, atol=1e-11)
        checked += 1
    assert checked > 20


def test_frames_are_fixed_to_the_macro_normal():
    """Turning both directions about +z leaves M unchanged (isotropic surface); at exactly
    normal incidence wi's frame is the limit of incidence planes at azimuth 0."""
    model = RoughDielectric("ggx", 0.3, 1.51)
    wi, wo = random_pairs(500, 4)
    t = 0.7
    turn = np.array([[np.cos(t), -np.sin(t), 0], [np.sin(t), np.cos(t), 0], [0, 0, 1]])
    np.testing.assert_allclose(model.eval_mueller(wi @ turn.T, wo @ turn.T),
                               model.eval_mueller(wi, wo), rtol=1e-10, atol=1e-13)
    wo = np.array([[0.5, 0.2, 0.84], [-0.3, 0.4, -0.87]])
    normal = model.eval_mueller([0.0, 0.0, 1.0], wo)
    near = model.eval_mueller([1e-9, 0.0, 1.0], wo)
    assert np.all(np.abs(normal - near) <= 1e-8 * normal[:, :1, :1])


def test_ms_adds_orders_two_and_up_to_m00_alone():
    """With multiple scattering the walk's orders >= 2 join M00 as unpolarised light; the
    polarised elements are single scattering's; orders >= 2 plus 1 make the whole walk."""
    model = RoughDielectric("ggx", 0.6, 1.51, masking="correlated", multiple_scattering=True)
    single = RoughDielectric("ggx", 0.6, 1.51, masking="correlated")
    wi = np.array([0.5, 0.0, 0.866])
    wo = np.array([[-0.5, 0.1, 0.86], [0.2, 0.3, -0.93], [0.7, 0.1, 0.7]])
    m = model.eval_mueller(wi, wo, rng=np.random.default_rng(5))
    m1 = single.eval_mueller(wi, wo)
    extra = m - m1
    assert np.all(extra[:, 0, 0] > 0)
    extra[:, 0, 0] = 0
    np.testing.assert_array_equal(extra, 0)
    walk = RandomWalkBSDF(single, walks=20000)
    whole = walk.estimate(wi, wo, np.random.default_rng(7))
    rest = walk.estimate(wi, wo, np.random.default_rng(8), min_order=2)
    gap = np.abs(m1[:, 0, 0] + rest.value - whole.value)
    assert np.all(gap < 5 * np.hypot(whole.stderr, rest.stderr)), (gap, whole, rest)


finite_z = st.sampled_from([0.0, 1e-300, -1e-300, 1e-9, -1e-9, 1e-15, -1e-15])
vectors = st.tuples(*[st.floats(-1, 1, allow_subnormal=True)] * 3).filter(
    lambda v: 1e-3 < np.linalg.norm(v))


@settings(max_examples=300, deadline=None, derandomize=True)
@given(wi=vectors, wo=vectors, zi=st.none() | finite_z, zo=st.none() | finite_z,
       log_alpha=st.floats(np.log(1e-4), np.log(4.0)),
       eta=st.sampled_from([0.25, 1 / 1.51, 1 - 1e-12, 1.0, 1 + 1e-12, 1.51, 4.0])
       | st.floats(0.25, 4.0),
       k=st.sampled_from([0.0, 1e-12, 1.0, 8.0]),
       dist=st.sampled_from(["ggx", "beckmann", "phong"]),
       masking=st.sampled_from(["separable", "correlated"]))
def test_every_mueller_matrix_is_finite_and_physically_realizable(wi, wo, zi, zo, log_alpha,
                                                                  eta, k, dist, masking):
    """Finite; M00 >= |(M01, M02, M03)| and |(M10, M20, M30)|; Cloude's coherency matrix has
    no eigenvalue below -1e-12 M00: every matrix is a physical (here non-depolarising) one."""
    wi, wo = np.array(wi), np.array(wo)
    wi[2], wo[2] = wi[2] if zi is None else zi, wo[2] if zo is None else zo
    if not (np.any(wi) and np.any(wo)):
        return
    alpha = float(np.exp(log_alpha))
    sampling = "walter" if dist == "phong" else "visible"
    for model in (RoughDielectric(dist, alpha, eta, masking=masking, sampling=sampling),
                  RoughConductor(dist, alpha, complex(eta, k), masking=masking,
                                 sampling=sampling)):
        m = model.eval_mueller(wi, wo)
        assert m.shape == (4, 4) and np.all(np.isfinite(m)) and m[0, 0] >= 0
        assert m[0, 0] == model.eval(wi, wo)
        tol = 1e-12 * m[0, 0]
        assert np.linalg.norm(m[0, 1:]) <= m[0, 0] + tol
        assert np.linalg.norm(m[1:, 0]) <= m[0, 0] + tol
        assert coherency_eigenvalues(m).min() >= -tol


def test_the_realizability_check_rejects_unphysical_matrices():
    """The coherency test has power: a Jones matrix's Mueller matrix passes with one
    non-zero eigenvalue; diag(1, 1, 1, -1) (not a Mueller matrix) and M00 < |M01| fail."""
    from model.bsdf.mueller import jones_diagonal_mueller

    good = jones_diagonal_mueller(0.3 + 0.4j, -0.8)
    eig = coherency_eigenvalues(good)
    assert eig.min() > -1e-15 and np.sum(eig > 1e-12) == 1
    assert coherency_eigenvalues(np.diag([1.0, 1, 1, -1])).min() < -0.1
    bad = np.eye(4)
    bad[0, 1] = 1.2
    assert coherency_eigenvalues(bad).min() < -0.1


@pytest.mark.parametrize("model", models()[:3] + models()[4:], ids=repr)
def test_compiled_kernel_matches_the_numpy_path(model):
    """backend numba (mueller_kernel) against the numpy reference: M00 is each backend's own
    eval exactly; M / M00 agrees to 1e-12 on random pairs, grazing and normal ones included."""
    pytest.importorskip("numba")
    reference = type(model)(**{**model_arguments(model), "backend": "numpy"})
    wi, wo = random_pairs(20000, 9)
    wi[:50, 2], wo[50:100, 2] = 1e-300, -1e-15
    wi[100:110], wo[110:120] = [0.0, 0.0, 1.0], [0.0, 0.0, -1.0]
    fast, slow = model.eval_mueller(wi, wo), reference.eval_mueller(wi, wo)
    assert model.backend == "numba"
    np.testing.assert_array_equal(fast[:, 0, 0], model.eval(wi, wo))
    live = (fast[:, 0, 0] > 1e-280) & (slow[:, 0, 0] > 1e-280)
    assert live.sum() > 4000  # a conductor scatters a quarter of random pairs
    np.testing.assert_allclose(fast[live] / fast[live, :1, :1],
                               slow[live] / slow[live, :1, :1], rtol=0, atol=1e-12)
    assert np.abs(fast[~live]).max() <= 1e-280 and np.abs(slow[~live]).max() <= 1e-280


def model_arguments(model) -> dict:
    """The constructor arguments that rebuild model (distribution, alpha, index, masking)."""
    d = model.distribution
    args = {"distribution": d.name, "alpha": (float(d.alpha_x), float(d.alpha_y)),
            "masking": model.masking}
    if isinstance(model, RoughConductor):
        return {**args, "eta_complex": model.eta_complex}
    return {**args, "eta": model.eta}
