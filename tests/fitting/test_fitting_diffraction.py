"""Fitting with the two-scale diffraction term: a polished-then-lapped metal on the emulated
bench (diffraction on: rms height 30 nm at 632.8 nm, correlation length 2 um) read by the
photodiode model at normal incidence is described by FitOptions(diffraction=True), which
recovers alpha, and not by the microfacet model alone; bad settings get one clear error."""

from __future__ import annotations

import argparse

import numpy as np
import pytest
from fitting_bench_runs import metered_bsdf

from calibration.fit import MS_CENTRE_WALKS, FitError, FitOptions, build_model, fit
from calibration.reduced import ReducedData
from sim.bench import build_bench

ALPHA = 0.08
NANO = {"rms_height_nm": 30.0, "correlation_length_um": 2.0, "psd_exponent": 2.0}
SAMPLE = {"kind": "conductor", "distribution": "ggx", "alpha": ALPHA, "eta": 0.2, "k": 3.4,
          "masking": "separable", "multiple_scattering": False, "diffraction": True, **NANO}
APERTURE = {"diameter_mm": 4.0, "distance_mm": 500.0}


def emulated_run(seed: int = 3, multiple_scattering: bool = False) -> ReducedData:
    """Reduced BSDF of an in-plane reflection scan at normal incidence, read by the photodiode
    model (noise, ranges, quantisation) from the bench's true power (aperture-integrated)."""
    sample = {**SAMPLE, "multiple_scattering": multiple_scattering}
    bench = build_bench({"sample": sample, "aperture": APERTURE, "seed": 1})
    assert bench.sample.diffraction_on(0.0)
    arms = np.concatenate([np.arange(-70.0, -5.0, 5.0), np.arange(7.0, 72.0, 5.0)])
    wi, wo, bsdf, sigma = metered_bsdf(bench, [(0.0, arm) for arm in arms], seed)
    half_angle = float(np.degrees(np.arctan(0.5 * APERTURE["diameter_mm"]
                                            / APERTURE["distance_mm"])))
    return ReducedData(wi=wi, wo=wo, bsdf=bsdf, sigma=sigma,
                       valid=np.ones(len(wi), bool), transmission=np.zeros(len(wi), bool),
                       meta={"eta": 0.2, "k": 3.4, "kind": "conductor", "wavelength_nm": 632.8,
                             "aperture_half_angle_deg": half_angle})


def options(diffraction: bool, **extra) -> FitOptions:
    nano = NANO if diffraction else {}
    return FitOptions(distributions=("ggx",), maskings=("separable",), diffraction=diffraction,
                      **nano, **extra)


@pytest.fixture(scope="module")
def data() -> ReducedData:
    return emulated_run()


def test_fit_with_diffraction_recovers_alpha(data):
    plain = fit(data, options(False))
    two_scale = fit(data, options(True))
    value, sigma = two_scale.param("alpha")
    print(f"alpha {ALPHA}: microfacet alone {plain.alpha:.5f} +- {plain.param('alpha')[1]:.5f}"
          f" (chi2/dof {plain.chi2_dof_fit:.3g}, {plain.fit_time_s:.2f} s), with diffraction "
          f"{value:.5f} +- {sigma:.5f} (chi2/dof {two_scale.chi2_dof_fit:.3g}, "
          f"{two_scale.fit_time_s:.2f} s)")
    assert two_scale.chi2_dof_fit < 2.0
    assert abs(value / ALPHA - 1.0) < 0.03 and abs(value - ALPHA) < 3.0 * sigma
    # the microfacet model alone cannot describe the diffracted light
    assert plain.chi2_dof_fit > 10.0 * two_scale.chi2_dof_fit
    out = two_scale.to_dict()
    assert out["diffraction"]["wavelength_nm"] == 632.8
    assert out["diffraction"]["rms_height_nm"] == NANO["rms_height_nm"]
    assert plain.to_dict()["diffraction"] is None
    from gonio_cli.commands.fit import summary

    text = summary({**out, "run": "emulated"})
    assert "diffraction: two-scale model, rms height 30 nm" in text and "fit time" in text
    # the result's predict() is the model the fit compared with the data
    r = (two_scale.predict(data.wi, data.wo) - data.bsdf) / data.sigma
    assert float(np.sum(r**2)) / (len(r) - 1) == pytest.approx(two_scale.chi2_dof_fit, rel=1e-6)


@pytest.mark.slow
def test_fit_combines_diffraction_with_multiple_scattering():
    """--multiple-scattering --diffraction on a bench with both on: single scattering inside
    the two-scale model plus the microsurface's orders >= 2 (as the bench has them) recovers
    alpha, reports both terms and its progress; its predict() is the fitted model. Every other
    point of the scan (two diffraction fits and a table: 29 s at load 16, bench included). The
    fit walks 2^16 per incidence: with 2^10 its orders >= 3 were off by more than their stated
    error against the bench's 2^16-walk tables (chi2/dof 22; 0.8 at 2^16)."""
    full = emulated_run(multiple_scattering=True)
    data = full.subset(np.arange(len(full.bsdf)) % 2 == 0)
    lines = []
    both = fit(data, options(True, multiple_scattering=True, ms_walks=1 << 16), lines.append)
    value, sigma = both.param("alpha")
    print(f"diffraction + multiple scattering: alpha {value:.5f} +- {sigma:.5f}, chi2/dof "
          f"{both.chi2_dof_fit:.3g} ({both.fit_time_s:.1f} s)")
    assert abs(value / ALPHA - 1.0) < 0.03 and abs(value - ALPHA) < 3.0 * sigma
    assert both.chi2_dof_fit < 2.0
    out = both.to_dict()
    assert out["diffraction"]["rms_height_nm"] == NANO["rms_height_nm"]
    assert out["multiple_scattering"] == {"walks": 1 << 16, "seed": 0,
                                          "fitted_walks": (1 << 16) * MS_CENTRE_WALKS}
    assert any("multiple-scattering table" in line for line in lines)
    assert all(line.startswith("fit: ggx/separable: ") for line in lines)
    f, err = both.predict_with_error(data.wi, data.wo)
    single = build_model("ggx", value, 0.2, "separable", 3.4, diffraction=both.diffraction)
    assert np.all(err > 0.0) and np.all(f > both.optics.average(single, data.wi, data.wo))


def test_diffraction_model_reduces_to_microfacet_for_a_smooth_nanosurface():
    """An independent limit: with 0.01 nm rms height the two-scale model is the microfacet
    one, so build_model's wrapper passes the wavelength and parameters through."""
    from calibration.fit import Diffraction

    wi = np.array([[0.0, 0.0, 1.0]] * 3)
    wo = np.array([[0.1, 0.0, 0.995], [0.3, 0.1, 0.949], [0.0, 0.0, 1.0]])
    wo = wo / np.linalg.norm(wo, axis=1, keepdims=True)
    plain = build_model("ggx", ALPHA, 0.2, "separable", 3.4).eval(wi, wo)
    smooth = build_model("ggx", ALPHA, 0.2, "separable", 3.4,
                         diffraction=Diffraction(0.01, 2.0, 2.0, 632.8)).eval(wi, wo)
    np.testing.assert_allclose(smooth, plain, rtol=1e-6)
    rough = build_model("ggx", ALPHA, 0.2, "separable", 3.4,
                        diffraction=Diffraction(30.0, 2.0, 2.0, 632.8)).eval(wi, wo)
    assert rough[2] < plain[2]  # the specular peak loses 1 - A to the diffraction lobe


def test_cli_flags_set_the_option():
    from gonio_cli.commands.fit import add_fit_options, options_from

    parser = argparse.ArgumentParser()
    add_fit_options(parser)
    on = options_from(parser.parse_args(["--diffraction", "--rms-height-nm", "25",
                                         "--correlation-length-um", "1.5",
                                         "--psd-exponent", "2.5"]))
    assert on.diffraction and (on.rms_height_nm, on.correlation_length_um,
                               on.psd_exponent) == (25.0, 1.5, 2.5)
    off = options_from(parser.parse_args([]))
    assert not off.diffraction and off == FitOptions(distributions=off.distributions,
                                                     maskings=off.maskings)


def test_cli_takes_the_nano_roughness_from_an_emulated_run_only(tmp_path):
    """An all-emulated run's [sim.sample] supplies what no flag gives; any other run's [sim]
    is never read (gonio.record.emulator_config gives None for it)."""
    from types import SimpleNamespace

    from gonio.record import emulator_config
    from gonio_cli.commands.fit import nano_roughness

    sim = {"sample": {"rms_height_nm": 40.0, "correlation_length_um": 3.0}}
    emulated = SimpleNamespace(config={"sim": sim}, meta={"sim": True})
    assert nano_roughness(emulator_config(emulated), None, None, None) == (40.0, 3.0, 2.0)
    assert nano_roughness(sim, 20.0, None, 3.0) == (20.0, 3.0, 3.0)  # a flag wins
    for meta in ({"sim": False}, {"sim": ["detector"]},
                 {"sim": True, "sessions": [{"sim": [], "endpoints": {"pm100": "/dev/tty1"}}]}):
        real = SimpleNamespace(config={"sim": sim}, meta=meta)
        assert nano_roughness(emulator_config(real), None, None, None) == (None, None, 2.0)


@pytest.mark.parametrize("settings, message", [
    ({"diffraction": True}, "rms_height_nm and correlation_length_um"),
    ({"diffraction": True, "rms_height_nm": 30.0}, "correlation_length_um"),
    ({**NANO, "diffraction": True, "rms_height_nm": -1.0}, "rms_height_nm must be positive"),
    ({**NANO, "diffraction": True, "psd_exponent": 1.0}, "psd_exponent"),
    ({**NANO, "diffraction": True, "diffraction_samples": 3}, "diffraction_samples"),
])
def test_bad_diffraction_settings_are_refused(settings, message):
    with pytest.raises(FitError, match=message):
        FitOptions(**settings)


def test_missing_wavelength_is_refused(data):
    from dataclasses import replace

    bare = replace(data, meta={"eta": 0.2, "k": 3.4, "kind": "conductor"})
    with pytest.raises(FitError, match="wavelength"):
        fit(bare, options(True))


def test_scanned_run_fits_with_diffraction_from_the_cli(tmp_path, capsys):
    """The real round trip (ptys, emulators, scan engine, run store, reduce): `gonio fit RUN
    --diffraction` takes the nano-roughness from the run's [sim.sample] and the wavelength from
    the reduced data, and recovers alpha; without it the fit is far worse."""
    import json

    from fitting_bench_runs import instrument, plan, scan

    from gonio_cli.main import main

    cfg = instrument(tmp_path, {"sample": SAMPLE, "aperture": {**APERTURE, "rtol": 1e-5}},
                     seed=3)
    grids = [{"side": "reflection", "theta_i_deg": 0.0,
              "theta_o_deg": {"start": 7.0, "stop": 70.0, "step": 3.5}}]
    metal = {"id": "lapped-metal", "kind": "conductor", "eta": 0.2, "k": 3.4}
    run = scan(plan(tmp_path, "lapped-metal", grids, dark_every=8, sample=metal), cfg,
               tmp_path / "runs")
    results = {}
    for flags in ([], ["--diffraction"]):
        assert main(["fit", str(run), "--json", "--distribution", "ggx", *flags]) == 0
        results[bool(flags)] = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    plain, two_scale = results[False], results[True]
    alpha = two_scale["parameters"]["alpha"]
    print(f"scanned: alpha {alpha['value']:.5f} +- {alpha['sigma']:.5f}, chi2/dof "
          f"{two_scale['chi2_dof_fit']:.3g} ({two_scale['n_fit']} points, "
          f"{two_scale['fit_time_s']:.2f} s); without diffraction alpha "
          f"{plain['parameters']['alpha']['value']:.5f}, chi2/dof {plain['chi2_dof_fit']:.3g}")
    assert two_scale["diffraction"]["rms_height_nm"] == NANO["rms_height_nm"]
    assert two_scale["diffraction"]["correlation_length_um"] == NANO["correlation_length_um"]
    assert two_scale["diffraction"]["wavelength_nm"] == pytest.approx(632.8)
    assert two_scale["chi2_dof_fit"] < 2.0
    assert abs(alpha["value"] / ALPHA - 1.0) < 0.03
    assert abs(alpha["value"] - ALPHA) < 3.0 * alpha["sigma"]
    assert plain["chi2_dof_fit"] > 10.0 * two_scale["chi2_dof_fit"]
