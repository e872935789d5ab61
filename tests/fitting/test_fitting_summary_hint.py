"""`gonio fit`'s summary: a rough sample fitted badly without multiple scattering gets a hint
to add it; a good fit, a smooth sample or a fit that has it gets none."""

import pytest

from gonio_cli.commands.fit import fit_warnings, summary


def fit_dict(alpha: float, chi2: float, multiple_scattering: bool) -> dict:
    out = {"run": "r", "distribution": "ggx", "masking": "separable",
           "parameters": {"alpha": {"value": alpha, "sigma": 1e-3},
                          "eta": {"value": 1.51, "fixed": True}},
           "chi2_dof_fit": chi2, "n_fit": 133, "chi2_dof_heldout": chi2, "n_heldout": 399,
           "candidates": [{"distribution": "ggx", "masking": "separable",
                           "chi2_dof_fit": chi2}],
           "clearly_preferred": True}
    if multiple_scattering:
        out["multiple_scattering"] = {"walks": 32768, "seed": 0}
    return out


@pytest.mark.parametrize("alpha, chi2, ms, hinted", [
    (0.40, 1.96e5, False, True),
    (0.40, 1.4, False, False),
    (0.023, 50.0, False, False),
    (0.40, 50.0, True, False),
])
def test_multiple_scattering_hint(alpha, chi2, ms, hinted):
    out = fit_dict(alpha, chi2, ms)
    out["warnings"] = fit_warnings(out)
    text = summary(out)
    assert ("try --multiple-scattering" in text) is hinted
    assert ("is well above 1" in text) is (chi2 > 3.0)
    assert ("model exports refuse this fit" in text) is (chi2 > 3.0)


def test_a_bad_held_out_chi2_warns_and_imported_data_names_no_run():
    out = dict(fit_dict(0.023, 1.2, False), chi2_dof_heldout=40.0)
    assert fit_warnings(out)[0].startswith("warning: chi2/dof 40 is well above 1")
    assert "gonio plot r --fit" in fit_warnings(out)[0]
    assert "gonio plot" not in fit_warnings(out, imported_from="data.astm")[0]
