"""A real third-party table fitted as a user fits it: NIST's measured BRDF of sintered PTFE
(Germer 2017, the unmodified PTFE.data.csv in ../shared/third_party/nist-ptfe-brdf, or
$GONIO_THIRD_PARTY; skipped where it is absent) made into an in-plane table at 532 nm by
examples/data/nist_ptfe_table.py and fitted by `gonio fit --import ... --json` with the
families of a diffuse sample. The JSON is consistent (each BIC is chi2 + k ln n, the choice is
the selection rule's, the margin is the BIC gap to another family), and the choice, every
candidate's BIC and chi2/dof and the skipped ones are those docs/fitting.md's table states."""

import json
import math
import re
import subprocess
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "conformance"))

from third_party import third_party  # noqa: E402

from calibration.fit.result import MAX_CHI2_DOF  # noqa: E402
from calibration.fit.select import KIND_FAMILIES  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
SOURCE = third_party("nist-ptfe-brdf") / "PTFE.data.csv"
SECTION = "## A real third-party table"
FAMILIES = "lambert,oren-nayar,lambert+microfacet,abg"

pytestmark = pytest.mark.skipif(
    not SOURCE.is_file(), reason=f"NIST's PTFE table is not at {SOURCE} (set GONIO_THIRD_PARTY "
    "to the third_party folder)")


def section() -> str:
    """docs/fitting.md's section on the real table."""
    text = (ROOT / "docs" / "fitting.md").read_text()
    return text.split(SECTION, 1)[1].split("\n## ", 1)[0]


def documented() -> tuple[str, dict[str, list[str]], set[str]]:
    """(the chosen candidate's label, the BIC, fitted and held-out chi2/dof cells of each fitted
    candidate by label, the labels of the skipped ones) of the section's table."""
    rows = [[cell.strip() for cell in line.strip().strip("|").split("|")]
            for line in section().splitlines() if line.startswith("| ") and "---" not in line]
    chosen, fitted, skipped = "", {}, set()
    for label, bic, chi2_fit, chi2_heldout, _ in rows[1:]:
        if label.endswith("(chosen)"):
            label = chosen = label.removesuffix("(chosen)").strip()
        if bic == "skipped":
            skipped.add(label)
        else:
            fitted[label] = [bic, chi2_fit, chi2_heldout]
    return chosen, fitted, skipped


def agrees(value: float, cell: str) -> bool:
    """True when `value` rounds to the documented cell (to its last digit, or 0.5 %)."""
    decimals = len(cell.partition(".")[2])
    return abs(value - float(cell)) <= max(0.6 * 10.0 ** -decimals, 0.005 * abs(float(cell)))


def label(candidate: dict) -> str:
    """A candidate as the docs name it: family[/distribution]."""
    return "/".join(filter(None, (candidate["family"], candidate["distribution"])))


def free(candidate: dict) -> int:
    """The number of parameters a candidate fitted (k of its BIC)."""
    return sum(not p.get("fixed") for p in candidate["parameters"].values())


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    """(the table's size, the scatter the script printed, `gonio fit --json`'s object)."""
    table = tmp_path_factory.mktemp("ptfe") / "ptfe-532.csv"
    made = subprocess.run([sys.executable, "examples/data/nist_ptfe_table.py", str(SOURCE),
                           str(table)], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert made.returncode == 0, made.stderr
    size = int(re.search(r": (\d+) points", made.stdout).group(1))
    scatter = re.search(r"normal incidence ([0-9.]+)", made.stdout).group(1)
    done = subprocess.run([sys.executable, "-m", "gonio_cli", "fit", "--import", str(table),
                           "--sigma-relative", scatter, "--eta", "1.35", "--incidence", "0,30,60",
                           "--family", FAMILIES, "--json"],
                          capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert done.returncode == 0, done.stderr
    return size, scatter, json.loads(done.stdout)


def test_the_table_is_the_documented_one(fitted):
    size, scatter, out = fitted
    assert size == 108 and out["n_fit"] + out["n_heldout"] == size
    assert f"--sigma-relative {scatter}" in section()
    assert out["noise_model"].startswith(f"assumed: u = {scatter} * |bsdf|")


def test_the_json_is_consistent(fitted):
    _, _, out = fitted
    assert out["criterion"] == "BIC" and out["family"] in KIND_FAMILIES["diffuse"]
    scored = [c for c in out["candidates"] if "failed" not in c]
    for c in scored:
        k, n = free(c), c["n_fit"]
        assert c["bic"] == pytest.approx(c["chi2_dof_fit"] * (n - k) + k * math.log(n))
    assert [c["bic"] for c in scored] == sorted(c["bic"] for c in scored)
    unrefuted = [c for c in scored
                 if c["n_heldout"] == 0 or c["chi2_dof_heldout"] <= MAX_CHI2_DOF]
    best = min(unrefuted or scored, key=lambda c: c["bic"])
    assert (out["family"], out["distribution"]) == (best["family"], best["distribution"])
    assert out["chi2_dof_fit"] == best["chi2_dof_fit"]
    assert out["chi2_dof_heldout"] == best["chi2_dof_heldout"]
    for name, p in best["parameters"].items():
        assert out["parameters"][name] == p
    assert out["parameters"]["eta"] == {"value": 1.35, "sigma": 0.0, "fixed": True}
    other = min(c["bic"] for c in scored if c["family"] != best["family"])
    assert out["preferred_by_delta_chi2"] == pytest.approx(other - best["bic"])
    assert out["clearly_preferred"] == (out["preferred_by_delta_chi2"] >= 4.0)


def test_the_choice_and_every_candidate_are_as_documented(fitted):
    _, _, out = fitted
    chosen, table, skipped = documented()
    assert label(out) == chosen
    scored = {label(c): c for c in out["candidates"] if "failed" not in c}
    assert scored.keys() == table.keys()
    for name, (bic, chi2_fit, chi2_heldout) in table.items():
        c = scored[name]
        assert agrees(c["bic"], bic), (name, c["bic"], bic)
        assert agrees(c["chi2_dof_fit"], chi2_fit), (name, c["chi2_dof_fit"], chi2_fit)
        assert agrees(c["chi2_dof_heldout"], chi2_heldout), (name, c["chi2_dof_heldout"])
    failed = [c["failed"] for c in out["candidates"] if "failed" in c]
    assert sorted(f.split(":", 1)[0] for f in failed) == sorted(skipped)
    assert all("ended at its bound" in f for f in failed)


def test_the_residuals_show_no_pattern_a_hint_names(fitted):
    _, _, out = fitted
    pattern = out["residual_pattern"]
    assert pattern["floor"] < 0 and not pattern["floor_flat"]
    assert pattern["retro"] == pattern["lobe"] == pattern["peak"] == 0.0
    assert f"z = {pattern['floor']:.1f}" in section().replace("−", "-").replace("\n", " ")
    assert len(out["warnings"]) == 1 and "model exports refuse this fit" in out["warnings"][0]
