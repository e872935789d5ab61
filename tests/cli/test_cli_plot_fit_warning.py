"""`gonio plot RUN --fit` warns on stderr of a fit whose chi2/dof says it does not describe the
data with the line `gonio fit` prints for the same fit (and its title still carries it): a run
scanned on the emulated serial bench (real ptys, instant motion), fitted at a wrong eta."""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "gonio"))
from gonio_testkit import fast_config, write_plan  # noqa: E402

from gonio.runner import new_scan  # noqa: E402
from gonio_cli.main import main  # noqa: E402

PLAN = {"name": "plot-warning", "dark": {"every": 8}, "beam": {"every": 8},
        "sample": {"id": "ground-glass", "kind": "hemisphere", "eta": 1.51, "lit_from": "air"},
        "grid": [{"side": "reflection", "theta_i_deg": [0.0, 30.0],
                  "theta_o_deg": {"start": -75.0, "stop": 75.0, "step": 15.0},
                  "skip_forbidden": True}]}
WRONG = ["--distribution", "ggx", "--eta", "1.2"]  # far from the sample's 1.51


def warnings_of(err: str, verb: str) -> list[str]:
    """stderr's `gonio VERB: warning: ...` lines, without the verb."""
    prefix = f"gonio {verb}: "
    return [ln[len(prefix):] for ln in err.splitlines()
            if ln.startswith(prefix) and "chi2/dof" in ln]


def test_plot_fit_prints_gonio_fits_warning_of_a_bad_fit(tmp_path, capsys):
    result = new_scan(write_plan(tmp_path, PLAN, fast_config()), sim=True,
                      out=tmp_path / "runs", progress=False)
    assert result.outcome.status == "completed"
    run = str(result.path)
    assert main(["fit", run, "--json", *WRONG]) == 0
    said = warnings_of(capsys.readouterr().err, "fit")
    assert len(said) == 1 and said[0].startswith("warning: chi2/dof ")
    assert main(["plot", run, "--fit", "--out", str(tmp_path / "p.png"), *WRONG]) == 0
    plotted = warnings_of(capsys.readouterr().err, "plot")
    assert plotted == [said[0].replace(f" (see gonio plot {run} --fit)", "")]
