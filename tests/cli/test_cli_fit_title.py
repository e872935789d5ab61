"""The fit overlay's title names eta once: the sample's nominal value in the run's line, the
fit's only when it says something new (fitted, or held at another value); it warns of a fit
whose chi2/dof says it does not describe the data, and names an incomplete run."""

from __future__ import annotations

from calibration.fit import FitOptions, fit
from calibration.fit.result import MAX_CHI2_DOF
from calibration.fitplot import fit_title, fit_warning
from calibration.plot import plot_title
from calibration.synthetic import synthesize

DATA = synthesize("ggx", 0.394, seed=3, incidences_deg=(0.0,), sides=("transmission",))
ONE = FitOptions(distributions=("ggx",))


def title_of(options: FitOptions) -> str:
    return fit_title(DATA, fit(DATA, options), plot_title("run", {**DATA.meta, "sample": {}}))


def test_eta_held_at_the_nominal_value_is_not_repeated():
    title = title_of(ONE)
    assert title.splitlines()[0] == "run: sample ?, eta 1.51"
    assert title.count("eta") + title.count("η") == 1 and "ggx fit α = 0.39" in title


def test_a_fitted_or_other_eta_is_shown():
    fitted = title_of(FitOptions(distributions=("ggx",), fit_eta=True))
    assert "(fitted)" in fitted.splitlines()[1] and "η = 1.5" in fitted
    held = title_of(FitOptions(distributions=("ggx",), eta=1.45))
    assert held.splitlines()[1].endswith("η = 1.45 (held)")


def test_a_fit_that_does_not_describe_the_data_says_so_in_its_title():
    good = title_of(ONE)
    assert "WARNING" not in good and fit_warning(fit(DATA, ONE)) == ""
    bad_fit = fit(DATA, FitOptions(distributions=("ggx",), eta=1.3))
    title = fit_title(DATA, bad_fit, "run")
    assert bad_fit.chi2_dof_fit > MAX_CHI2_DOF
    assert title.splitlines()[-1] == (
        f"WARNING: fitted χ²/dof {bad_fit.chi2_dof_fit:.3g} > {MAX_CHI2_DOF:g}: the model does "
        "not describe the data within their uncertainties")


def test_an_incomplete_run_says_so_under_the_run_line():
    facts = {"status": "aborted", "reason": "aborted by the user", "complete": False,
             "stored_readings": 51, "planned_readings": 588}
    title = plot_title("run", {**DATA.meta, "sample": {}, "completeness": facts})
    assert title.splitlines() == ["run: sample ?, eta 1.51", "incomplete run: 51 of 588 "
                                  "readings stored, status aborted (aborted by the user)"]
    whole = {**facts, "status": "completed", "reason": "", "complete": True,
             "stored_readings": 588}
    assert plot_title("run", {**DATA.meta, "sample": {}, "completeness": whole}) == \
        "run: sample ?, eta 1.51"


def test_a_family_fit_overlays_under_its_family_with_its_held_parameters(tmp_path):
    from calibration.fit import select
    from calibration.fitplot import plot_fit
    from calibration.synthetic import synthesize_family

    data = synthesize_family("lambert+microfacet", {"rho": 0.5, "alpha": 0.15, "eta": 1.5},
                             {"distribution": "ggx"}, seed=3)
    result = select(data, FitOptions(families=("lambert+microfacet",),
                                     distributions=("ggx",)))
    title = fit_title(data, result, "run")
    assert title.splitlines()[1].startswith("lambert+microfacet (rho = ")
    assert "eta = 1.5" in title.splitlines()[1]  # held at the sample's index, still shown
    png = plot_fit(data, result, tmp_path / "fit.png", FitOptions(), title="run")
    assert png.stat().st_size > 0
