"""A real run is reduced, plotted and exported from what the experimenter describes ([optics],
[sample], the calibration), never from the emulator's [sim]: the same readings reduce
bitwise identically under a deliberately wrong [sim] and under none; a missing description is
one clear error; the emulator's truth is drawn for emulated runs only; every export carries the
run's record (optics, sample, calibration, devices per session)."""

import csv
import json
import shutil

import numpy as np
import pytest
from gonio_testkit import fast_config, gonio_cli, one_line_error, rewrite_run_files, write_toml

from calibration import calfile
from calibration.pipeline import reduce_run
from calibration.plot import emulated_truth, plot_reduced, plot_title, truth_curves
from calibration.values import Measured
from gonio.config import parse_config
from gonio.errors import ConfigError
from gonio.record import run_record
from gonio.runner import new_scan
from gonio.store import open_run
from sim.truth import TRUTH, emulator_shot_noise_w

PLAN = {"name": "record", "averaging": 4, "order": "as-written",
        "sample": {"id": "GG-7", "kind": "hemisphere", "eta": 1.51, "operator": "test"},
        "grid": [{"side": "transmission", "theta_i_deg": 0.0,
                  "theta_o_deg": {"start": -45.0, "stop": 45.0, "step": 7.5}},
                 {"side": "reflection", "theta_i_deg": 0.0,
                  "theta_o_deg": {"start": 15.0, "stop": 60.0, "step": 15.0}}],
        "dark": {"every": 4}, "beam": {"every": 8}}
#: Everything the emulator pretends, wrong: another sample, aperture, meter and seed.
WRONG_SIM = {"time_scale": "inf", "seed": 99,
             "sample": {"distribution": "beckmann", "alpha": 0.05, "eta": 1.3},
             "aperture": {"diameter_mm": 20.0, "distance_mm": 300.0},
             "detector": {"read_noise_fraction": 1e-2, "bandwidth_hz": 1e6}}
IDENTITY = {"pm100": {"protocol": "pm100", "endpoint": "/dev/ttyUSB0",
                      "identity": {"idn": "Thorlabs,PM100USB,P2000123,1.4.0"}}}


@pytest.fixture(scope="module")
def emulated(tmp_path_factory):
    """One emulated run of a ground-glass hemisphere (sim-serial, instant motion)."""
    tmp = tmp_path_factory.mktemp("record")
    cfg = fast_config()
    cfg["sim"]["detector"] = {"read_noise_fraction": 2e-5}  # so that shot noise shows
    write_toml(tmp / "instrument.toml", cfg)
    plan = write_toml(tmp / "plan.toml", {**PLAN, "instrument": "instrument.toml"})
    result = new_scan(plan, out=tmp / "runs", sim=True, progress=False)
    assert result.outcome.status == "completed", result.outcome
    return result.path


def as_real(run_dir, to, sim=None, drop=(), sessions_devices=None):
    """A copy of a run whose meta says its devices were real: config.json's [sim] replaced by
    `sim` (or removed), `drop` tables removed from config.json ("optics") or plan.json
    ("sample")."""
    shutil.copytree(run_dir, to)
    meta = json.loads((to / "meta.json").read_text())
    meta["sim"], meta["seeds"] = False, {}
    for session in meta["sessions"]:
        session["sim"] = []
        if sessions_devices is not None:
            session["devices"] = sessions_devices
    for name in drop:
        meta[name] = None
    (to / "meta.json").write_text(json.dumps(meta))
    config = json.loads((to / "config.json").read_text())
    config.pop("sim")
    if sim is not None:
        config["sim"] = sim
    plan = json.loads((to / "plan.json").read_text())
    if "optics" in drop:
        config.pop("optics")
    if "sample" in drop:
        plan.pop("sample")
    rewrite_run_files(to, plan, config)
    return to


def test_a_real_run_reduces_the_same_under_a_wrong_sim_and_none(emulated, tmp_path):
    wrong = reduce_run(as_real(emulated, tmp_path / "wrong", WRONG_SIM))
    bare = reduce_run(as_real(emulated, tmp_path / "bare"))
    for name in ("bsdf", "sigma", "valid", "wi", "wo"):
        np.testing.assert_array_equal(getattr(wrong, name), getattr(bare, name), strict=True)
    assert ({k: v for k, v in wrong.meta.items() if k != "run"}
            == {k: v for k, v in bare.meta.items() if k != "run"})
    assert wrong.meta["sim"] is None and wrong.meta["emulator_truth"] is None
    assert "shot noise not modelled" in wrong.meta["noise_model"]
    # the emulated original differs only by the shot noise its meter states
    own = reduce_run(emulated)
    np.testing.assert_array_equal(own.bsdf, wrong.bsdf, strict=True)
    assert own.valid.sum() > 10 and np.all(own.sigma[own.valid] >= wrong.sigma[own.valid])
    assert np.any(own.sigma[own.valid] > wrong.sigma[own.valid])
    assert "[sim.detector]" in own.meta["noise_model"]
    config = open_run(emulated).config
    stated = reduce_run(tmp_path / "wrong", shot_noise_w=emulator_shot_noise_w(
        config["sim"]["detector"], config["optics"]["wavelength_nm"]))
    np.testing.assert_array_equal(own.sigma, stated.sigma, strict=True)
    assert "from --shot-noise-w, averaged over 4" in stated.meta["noise_model"]
    described = json.loads((tmp_path / "bare" / "config.json").read_text())
    described["detector"]["shot_noise_w"] = emulator_shot_noise_w(
        config["sim"]["detector"], config["optics"]["wavelength_nm"])
    rewrite_run_files(tmp_path / "bare", config=described)
    from_config = reduce_run(tmp_path / "bare")
    np.testing.assert_array_equal(own.sigma, from_config.sigma, strict=True)
    assert "from [detector] shot_noise_w" in from_config.meta["noise_model"]
    described["detector"]["shot_noise_w"] = -1.0
    with pytest.raises(ConfigError, match=r"config: \[detector\] shot_noise_w: must be in"):
        parse_config(described)


def test_a_run_without_its_description_is_one_error_unless_calibrated(emulated, tmp_path):
    bare = as_real(emulated, tmp_path / "bare", drop=("optics", "sample"))
    done = gonio_cli("reduce", bare)
    assert done.returncode != 0
    line = one_line_error(done.stderr)
    for needed in ("plan's [sample] table (id, kind, eta", "instrument config's [optics] table",
                   "aperture_diameter_mm", "gonio calibrate build"):
        assert needed in line, line
    # a calibration that measured the aperture stands in for the missing [optics]
    no_optics = as_real(emulated, tmp_path / "no-optics", drop=("optics",))
    cal = calfile.Calibration(created_utc="2026-01-01T00:00:00Z",
                              aperture_half_angle_deg=Measured(0.6, 0.01))
    path = calfile.save(cal, tmp_path / "cal.json")
    data = reduce_run(no_optics, path)
    assert data.meta["aperture_from"] == "calibration"
    assert data.meta["aperture_half_angle_deg"] == 0.6 and data.valid.sum() > 10


def test_the_emulator_truth_is_drawn_for_emulated_runs_only(emulated, tmp_path):
    own = reduce_run(emulated)
    real = reduce_run(as_real(emulated, tmp_path / "real", WRONG_SIM))
    labels = list(truth_curves(own.meta, emulated_truth(own.meta), 0.0, True))
    assert labels and all(label.startswith(TRUTH) for label in labels)
    assert not any("model" in label for label in labels)
    assert emulated_truth(real.meta) is None
    assert truth_curves(real.meta, None, 0.0, True) == {}
    assert plot_title("r", own.meta) == "r: sample GG-7, eta 1.51"
    for name, data in (("emulated", own), ("real", real)):
        assert plot_reduced(data, tmp_path / f"{name}.png", title=name).stat().st_size > 0


def header(path):
    """The `# key: JSON` lines of a CSV export, parsed."""
    lines = [ln[2:] for ln in path.read_text().splitlines() if ln.startswith("# ")]
    return {key: json.loads(value) for key, value in (ln.split(": ", 1) for ln in lines)}


def test_every_export_carries_the_record(emulated, tmp_path):
    import netCDF4

    from calibration.exports import ExportRequest
    from calibration.exports import write as write_export
    from calibration.exports.raw import write_csv, write_netcdf
    from calibration.formats import FORMATS

    run = open_run(as_real(emulated, tmp_path / "real", WRONG_SIM, sessions_devices=IDENTITY))
    record = run_record(run)
    facts = header(write_csv(run, tmp_path / "run.csv"))
    assert facts == json.loads(json.dumps(record))
    assert facts["wavelength_nm"] == 632.8 and facts["bandwidth_nm"] == 0.002
    assert facts["receiver_solid_angle_sr"] == pytest.approx(3.1413570537740097e-4)
    assert (facts["beam_diameter_mm"], facts["beam_divergence_half_angle_deg"]) == (2.0, 0.03)
    assert facts["source_polarisation"] == facts["analyser_polarisation"] == "unpolarised"
    assert facts["sample"]["id"] == "GG-7" and facts["sample"]["operator"] == "test"
    assert facts["provenance"]["lab"] == "gonio emulated bench" and facts["environment"] is None
    assert facts["light_source"]["source_power_mw"] == 1.0 and facts["detector"] == "pm100"
    assert "calibration" in facts and facts["emulated"] is False
    assert facts["sessions"][0]["devices"] == IDENTITY
    with open(tmp_path / "run.csv") as fh:  # the data rows still read as CSV
        rows = list(csv.reader(ln for ln in fh if not ln.startswith("#")))
    assert rows[0][:2] == ["index", "kind"] and len(rows) == len(run) + 1
    with netCDF4.Dataset(write_netcdf(run, tmp_path / "run.nc")) as ds:
        assert ds.wavelength_nm == 632.8 and ds.receiver_solid_angle_sr == pytest.approx(
            3.1413570537740097e-4)
        assert ds.source_polarisation == "unpolarised"
        assert json.loads(ds.sample)["id"] == "GG-7"
        assert json.loads(ds.sessions)[0]["devices"] == IDENTITY
    # the reduced exports and the model's (forced: this short run's fit is not the point)
    forced = ExportRequest(force=True)
    texts = [write_export(run.path, fmt, tmp_path / f"glass{FORMATS[fmt].suffixes[0]}",
                          forced)[0][0].read_text() for fmt in ("csv", "zemax", "astm", "mitsuba")]
    for line in ('# receiver_solid_angle_sr: ', '# sample: {"id": "GG-7"',
                 '# sessions: [{"session": 0'):
        for text in texts[:3]:
            assert line in text
        assert line[2:] in texts[3]
    with netCDF4.Dataset(write_export(run.path, "netcdf", tmp_path / "reduced.nc")[0][0]) as ds:
        assert "bsdf" in ds.variables and json.loads(ds.sample)["id"] == "GG-7"
    # an emulated run from before device identities names its endpoints per session
    old = run_record(open_run(emulated))["sessions"][0]
    assert old["emulated"] and set(old["devices"]) == set(open_run(emulated).config["devices"])
