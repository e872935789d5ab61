"""The fit overlay's title names eta once: the sample's nominal value in the run's line, the
fit's only when it says something new (fitted, or held at another value)."""

from __future__ import annotations

from calibration.fit import FitOptions, fit
from calibration.fitplot import fit_title
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
