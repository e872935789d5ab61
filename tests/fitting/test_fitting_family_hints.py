"""`gonio fit`'s hints follow the residuals (calibration.fit.pattern): data drawn from one family
and fitted by another that lacks what they have get the hint that names it, and a good fit none."""

import pytest

from calibration.fit import FitOptions, build_model, select
from calibration.synthetic import drawn, in_plane_directions, synthesize, synthesize_family
from gonio_cli.commands.fit import fit_warnings

COAT = {"rho": 0.5, "alpha": 0.15, "eta": 1.5}
FLOOR = "a diffuse floor): add a diffuse term, try --family lambert+microfacet"
BACK = "back-scatter of a rough matte surface): try --family oren-nayar"
LOBE = "the model's lobe is wider than the data's about the specular direction"
PEAK = "the data peak about the specular direction, which lambert does not"
MS = "try --multiple-scattering"


def hints(data, families: tuple[str, ...], distributions: tuple[str, ...]) -> list[str]:
    """The hint lines `gonio fit` prints for the fit of `data` by the given candidates, fitted
    at 0 and 60 deg (normal incidence alone leaves Oren-Nayar's sigma free) and held out at 30."""
    out = select(data, FitOptions(families=families, distributions=distributions,
                                  fit_incidence_deg=(0.0, 60.0))).to_dict()
    out["run"] = "data.csv"
    return [line for line in fit_warnings(out, imported_from="data.csv")
            if line.startswith("hint:")]


@pytest.mark.parametrize("name, data, families, distributions, expected", [
    ("a coated panel fitted by the microfacet interface alone",
     synthesize_family("lambert+microfacet", COAT, {"distribution": "ggx"}, seed=2),
     ("microfacet",), ("ggx",), FLOOR),
    ("a rough matte surface fitted by Lambert",
     synthesize_family("oren-nayar", {"rho": 0.7, "sigma": 0.5}, seed=2),
     ("lambert",), ("ggx",), BACK),
    ("a GGX lobe fitted by Beckmann",
     synthesize("ggx", 0.2, incidences_deg=(0.0, 30.0, 60.0), sides=("reflection",), seed=2),
     ("microfacet",), ("beckmann",), LOBE),
    ("a coated panel fitted by Lambert",
     synthesize_family("lambert+microfacet", COAT, {"distribution": "ggx"}, seed=2),
     ("lambert",), ("ggx",), PEAK),
], ids=lambda v: v if isinstance(v, str) and " " in v else "")
def test_the_hint_names_what_the_residuals_show(name, data, families, distributions,
                                                expected):
    given = hints(data, families, distributions)
    assert len(given) == 1 and expected in given[0], (name, given)
    assert MS not in given[0]


def test_a_good_fit_gets_no_hint():
    data = synthesize_family("oren-nayar", {"rho": 0.7, "sigma": 0.5}, seed=2)
    assert hints(data, ("oren-nayar",), ("ggx",)) == []


def test_a_rough_glass_fitted_without_multiple_scattering_gets_that_hint():
    """Light scattered more than once lifts a rough dielectric's data over a broad lobe, not a
    flat floor: the hint is multiple scattering, not a diffuse term."""
    model = build_model("ggx", 0.45, 1.51, "separable", walks=1 << 14, seed=1)
    data = drawn(model, [in_plane_directions(t, 1.51, 0.45) for t in (0.0, 30.0, 60.0)],
                 0.02, 1e6, 3, {"eta": 1.51, "kind": "hemisphere"})
    out = select(data, FitOptions(distributions=("ggx",))).to_dict()
    assert out["residual_pattern"]["floor"] > 0 and not out["residual_pattern"]["floor_flat"]
    given = [line for line in fit_warnings(dict(out, run="r"), imported_from="data.csv")
             if line.startswith("hint:")]
    assert len(given) == 1 and MS in given[0] and "--family" not in given[0]


def test_a_polished_metal_fitted_without_diffraction_gets_that_hint():
    """A polished surface's nano-roughness halo lifts the data beside a narrow lobe, falling
    away from it: the hint is the two-scale diffraction term, not a diffuse one."""
    from calibration.fit import Diffraction

    model = build_model("ggx", 0.003, 1.37, "separable", 7.62,
                        diffraction=Diffraction(5.0, 5.0, 2.0, 632.8))
    data = drawn(model, [in_plane_directions(t, 1.37, 0.05, sides=("reflection",))
                         for t in (0.0, 30.0, 60.0)], 0.02, 1e9, 3,
                 {"eta": 1.37, "k": 7.62, "kind": "conductor", "wavelength_nm": 632.8})
    out = select(data, FitOptions(distributions=("ggx",))).to_dict()
    assert out["residual_pattern"]["floor"] > 0 and not out["residual_pattern"]["floor_flat"]
    given = [line for line in fit_warnings(dict(out, run="r"), imported_from="data.csv")
             if line.startswith("hint:")]
    assert any("try --diffraction" in line for line in given), given
    assert not any(FLOOR in line or MS in line for line in given), given
