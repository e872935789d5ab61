"""Fits of the model families beside the microfacet interface (calibration.fit.select) on data
drawn from each family with a known sigma: each recovered within its uncertainty, the true
family chosen among those the sample's kind allows, data known up to a scale (--relative), and
the `family` field of `gonio fit --json`, through the command line as a user runs it."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from calibration.fit import FitError, FitOptions, fit, select
from calibration.fit.select import KIND_FAMILIES, bic
from calibration.synthetic import synthesize, synthesize_family

ROOT = Path(__file__).resolve().parents[2]
COAT = {"rho": 0.5, "alpha": 0.15, "eta": 1.5}
TRUTHS = [
    ("lambert", {"rho": 0.6}, {}),
    ("oren-nayar", {"rho": 0.7, "sigma": 0.4}, {}),
    ("lambert+microfacet", COAT, {"distribution": "ggx"}),
    ("abg", {"A": 0.02, "B": 0.01, "g": 2.0}, {}),
]


def within(result, truth: dict, pulls: float = 3.0) -> None:
    """Every fitted parameter of `truth` within `pulls` of its sigma of the true value."""
    for name, value in truth.items():
        fitted, sigma = result.param(name)
        assert sigma > 0 and abs(fitted - value) < pulls * sigma, (name, fitted, sigma, value)


@pytest.mark.parametrize("family, truth, settings", TRUTHS, ids=[t[0] for t in TRUTHS])
def test_each_family_is_recovered_within_its_sigma(family, truth, settings):
    data = synthesize_family(family, truth, settings, seed=5)
    result = select(data, FitOptions(families=(family,), distributions=("ggx",),
                                     fit_incidence_deg=None))
    fixed = {"eta": 1.5} if "eta" in truth else {}  # the sample's nominal index, held
    within(result, {k: v for k, v in truth.items() if k not in fixed})
    assert result.family == family and result.settings == (
        {"distribution": "ggx", "masking": "separable"} if settings else {})
    assert result.fixed == fixed
    assert 0.7 < result.chi2_dof_fit < 1.3


@pytest.mark.parametrize("family, truth, settings, kind", [
    ("oren-nayar", {"rho": 0.7, "sigma": 0.4}, {}, "reference"),
    ("lambert", {"rho": 0.9}, {}, "reference"),
    ("lambert+microfacet", COAT, {"distribution": "ggx"}, "coated"),
    ("abg", {"A": 0.02, "B": 0.01, "g": 2.0}, {}, "coated"),
])
def test_selection_picks_the_true_family_by_bic_with_held_out_points(family, truth, settings,
                                                                     kind):
    data = synthesize_family(family, truth, settings, seed=7)
    data.meta["kind"] = kind
    # fitted at 0 and 60 deg (normal incidence alone leaves Oren-Nayar's sigma free), 30 held
    result = select(data, FitOptions(distributions=("ggx",), fit_incidence_deg=(0.0, 60.0)))
    assert result.family == family and result.criterion == "BIC"
    assert result.n_heldout > 0.4 * result.n_fit and result.chi2_dof_heldout < 1.5
    scored = [c for c in result.candidates if "failed" not in c]
    assert {c["family"] for c in scored} | {c["failed"].split("/")[0].split(":")[0]
                                            for c in result.candidates if "failed" in c} \
        == set(KIND_FAMILIES[kind])
    assert scored[0]["family"] == family
    assert [c["bic"] for c in scored] == sorted(c["bic"] for c in scored)
    n_params = len(scored[0]["parameters"])
    chi2 = scored[0]["chi2_dof_fit"] * (scored[0]["n_fit"] - n_params)
    assert scored[0]["bic"] == pytest.approx(bic(chi2, n_params, scored[0]["n_fit"]))
    if len(scored) > 1:
        assert result.preferred_by == pytest.approx(scored[1]["bic"] - scored[0]["bic"])


def test_a_microfacet_sample_fits_exactly_as_the_microfacet_fit():
    data = synthesize("ggx", 0.394, eta=1.51, seed=11)
    data.meta["kind"] = "hemisphere"
    chosen, plain = select(data), fit(data)
    assert chosen.family == "microfacet" and chosen.criterion is None
    assert np.array_equal(chosen.values, plain.values) and chosen.candidates == plain.candidates
    out = chosen.to_dict()
    assert out["family"] == "microfacet" and out["distribution"] == "ggx"
    assert out["parameters"]["alpha"].keys() == {"value", "sigma"}


def test_relative_data_recover_the_scale_and_the_parameters():
    data = synthesize_family("lambert+microfacet", COAT, {"distribution": "ggx"}, seed=3,
                             scale=2.5)
    result = select(data, FitOptions(families=("lambert+microfacet",), distributions=("ggx",),
                                     fit_scale=True, fit_incidence_deg=None))
    within(result, {"rho": 0.5, "alpha": 0.15, "scale": 2.5})
    assert result.to_dict()["parameters"]["scale"]["sigma"] > 0


def test_relative_lambert_data_carry_the_level_in_the_scale():
    """Lambert's BSDF is proportional to rho, which a scale cannot be told from: rho is held
    at its default and the scale carries the level (rho x scale is what the data give)."""
    data = synthesize_family("lambert", {"rho": 0.6}, seed=3, scale=0.2)
    result = select(data, FitOptions(families=("lambert",), fit_scale=True,
                                     fit_incidence_deg=None))
    assert result.names == ("scale",) and result.fixed == {"rho": 0.8}
    value, sigma = result.param("scale")
    assert abs(0.8 * value - 0.6 * 0.2) < 3.0 * 0.8 * sigma


def test_unknown_families_and_no_fitting_family_are_one_error():
    with pytest.raises(FitError, match="unknown family 'glossy'; known: microfacet, lambert"):
        FitOptions(families=("glossy",))
    data = synthesize_family("lambert", {"rho": 0.6}, seed=3)
    with pytest.raises(FitError, match="no family fitted: lambert\\+microfacet/phong/separable"):
        select(data, FitOptions(families=("lambert+microfacet",), distributions=("phong",)))


def write_table(path: Path, data, incidence: float) -> None:
    """A plain CSV table of one incidence: signed in-plane theta_o (positive on the specular
    side), value and sigma, with the incidence and the index in header lines."""
    theta_o = np.degrees(np.arctan2(data.wo[:, 0], data.wo[:, 2]))  # the source is at -x
    rows = "".join(f"{t:.6f},{v:.9g},{s:.6g}\n"
                   for t, v, s in zip(theta_o, data.bsdf, data.sigma, strict=True))
    path.write_text(f"# theta_i_deg: {incidence:g}\n# eta: 1.5\ntheta_o_deg,value,sigma\n"
                    + rows)


def test_gonio_fit_json_names_the_family_of_a_relative_single_incidence_table(tmp_path):
    data = synthesize_family("lambert+microfacet", COAT, {"distribution": "ggx"}, seed=3,
                             scale=2.5, incidences_deg=(30.0,))
    table = tmp_path / "coated-30deg.csv"
    write_table(table, data, 30.0)
    done = subprocess.run([sys.executable, "-m", "gonio_cli", "fit", "--import", str(table),
                           "--relative", "--family", "lambert+microfacet,lambert,abg",
                           "--distribution", "ggx", "--json"],
                          capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert done.returncode == 0, done.stderr
    out = json.loads(done.stdout)
    assert out["family"] == "lambert+microfacet" and out["distribution"] == "ggx"
    assert out["criterion"] == "BIC" and out["n_fit"] == len(data.bsdf)
    params = out["parameters"]
    for name, truth in (("rho", 0.5), ("alpha", 0.15), ("scale", 2.5)):
        assert abs(params[name]["value"] - truth) < 3.0 * params[name]["sigma"], name
    assert params["eta"] == {"value": 1.5, "sigma": 0.0, "fixed": True}
    scored = [c for c in out["candidates"] if "failed" not in c]
    assert [c["family"] for c in scored][:1] == ["lambert+microfacet"] and len(scored) >= 2
    assert all({"bic", "chi2_dof_fit", "chi2_dof_heldout", "parameters"} <= c.keys()
               for c in scored)
    summary = subprocess.run([sys.executable, "-m", "gonio_cli", "fit", "--import", str(table),
                              "--relative", "--family", "lambert+microfacet",
                              "--distribution", "ggx"],
                             capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert summary.returncode == 0, summary.stderr
    assert f"run {table}: lambert+microfacet/ggx/separable" in summary.stdout
    assert "-> lambert+microfacet by BIC" in summary.stdout


def test_a_fit_at_the_default_incidence_of_data_without_it_takes_their_lowest():
    data = synthesize_family("abg", {"A": 0.02, "B": 0.01, "g": 2.0}, seed=7,
                             incidences_deg=(10.0, 45.0))
    result = select(data, FitOptions(families=("abg",)))  # fit_incidence_deg left at 0
    assert result.n_fit == int(np.sum(np.abs(data.theta_i_deg - 10.0) < 0.5))
    assert result.n_heldout == int(np.sum(np.abs(data.theta_i_deg - 45.0) < 0.5))
    with pytest.raises(FitError, match="only 0 usable points at incidence 30 deg"):
        select(data, FitOptions(families=("abg",), fit_incidence_deg=(30.0,)))  # as asked
