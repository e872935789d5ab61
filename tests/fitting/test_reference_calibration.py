"""Reference-standard calibration without a bench: the certificate file (its checks, one error per
malformed field, multilinear interpolation, refusal outside its grid), the effective solid
angle a reference run's reduction gives against it, and reductions normalised to it, which
carry the certificate's and the reference run's uncertainty as shared components."""

from __future__ import annotations

import dataclasses
import itertools
import math

import numpy as np
import pytest
from budget_kit import spec_run, spec_scan

from calibration import calfile, certificate
from calibration.calfile import Calibration
from calibration.calsummary import applied
from calibration.reduce import optics_of, reduce_readings
from calibration.reduced import ReducedData
from calibration.reference import ReferenceScale, relative_azimuth_deg, scale_from
from calibration.values import CalibrationError, Measured

WAVELENGTHS, THETA_I, THETA_O, PHI = (500.0, 700.0), (0.0, 40.0), (0.0, 30.0, 80.0), (0.0, 180.0)


def linear_value(wl, ti, to, phi):
    """A value linear in each coordinate, which multilinear interpolation reproduces."""
    return 0.9 + 1e-4 * (wl - 500.0) - 1e-3 * ti - 5e-4 * to + 2e-4 * phi


def certificate_text(quantity="reflectance_factor", k=2.0, drop=None, extra_point="",
                     header_extra="", with_phi=True) -> str:
    """A certificate's TOML: the linear value on the full grid, U = 1 % of it."""
    lines = ['format = "gonio-reference-certificate/1"', 'id = "TEST-42"',
             'issuer = "a test"', "date = 2026-11-30", f'quantity = "{quantity}"',
             f"coverage_k = {k}", header_extra]
    grid = itertools.product(WAVELENGTHS, THETA_I, THETA_O, PHI if with_phi else (None,))
    for n, (wl, ti, to, phi) in enumerate(grid):
        if n == drop:
            continue
        v = linear_value(wl, ti, to, phi or 0.0)
        at = f"wavelength_nm = {wl}, theta_i_deg = {ti}, theta_o_deg = {to}"
        at += f", phi_deg = {phi}" if with_phi else ""
        lines.append(f"[[point]]\n{at.replace(', ', chr(10))}\nvalue = {v!r}\nU = {0.01 * v!r}")
    return "\n".join(lines) + "\n" + extra_point


def write(tmp_path, text: str, name: str = "cert.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_a_certificate_interpolates_multilinearly_and_converts_reflectance_factor(tmp_path):
    cert = certificate.load(write(tmp_path, certificate_text()))
    ti, to, phi = np.array([0.0, 13.0, 40.0]), np.array([45.0, 2.5, 80.0]), np.array([90.0, 0, 7])
    f, u = cert.brdf_at(612.0, ti, to, phi)
    truth = linear_value(612.0, ti, to, phi) / math.pi  # R = pi f
    np.testing.assert_allclose(f, truth, rtol=1e-12)
    np.testing.assert_allclose(u, 0.01 * truth / 2.0, rtol=1e-12)  # U / k
    assert cert.to_json()["id"] == "TEST-42" and len(cert.to_json()["sha256"]) == 64
    brdf = certificate.load(write(tmp_path, certificate_text("brdf"), "b.toml"))
    np.testing.assert_allclose(brdf.brdf_at(612.0, ti, to, phi)[0], truth * math.pi)


def test_a_certificate_without_azimuths_holds_at_every_azimuth(tmp_path):
    cert = certificate.load(write(tmp_path, certificate_text(with_phi=False)))
    f, _ = cert.brdf_at(600.0, np.array([10.0, 10.0]), np.array([20.0, 20.0]),
                        np.array([0.0, 180.0]))
    assert f[0] == f[1] == pytest.approx(linear_value(600.0, 10.0, 20.0, 0.0) / math.pi)


def test_points_outside_the_grid_are_refused_and_its_edges_tolerate_a_stage_offset(tmp_path):
    cert = certificate.load(write(tmp_path, certificate_text()))
    with pytest.raises(CalibrationError, match=r"covers wavelength_nm 500 to 700 only; a "
                                               r"point at wavelength_nm 800 is outside it"):
        cert.brdf_at(800.0, np.array([0.0]), np.array([10.0]), np.array([0.0]))
    with pytest.raises(CalibrationError, match="theta_i_deg 0 to 40 only.*at theta_i_deg 41"):
        cert.brdf_at(600.0, np.array([10.0, 41.0]), np.array([10.0, 10.0]), np.zeros(2))
    edge = cert.brdf_at(600.0, np.array([40.3]), np.array([10.0]), np.array([0.0]))[0]
    assert edge == pytest.approx(cert.brdf_at(600.0, np.array([40.0]), np.array([10.0]),
                                              np.array([0.0]))[0])


POINT = "\n[[point]]\nwavelength_nm = 500.0\ntheta_i_deg = 0.0\ntheta_o_deg = 0.0\nphi_deg = 0.0"


@pytest.mark.parametrize(("change", "message"), [
    ({"text": "id = "}, "not valid TOML"),
    ({"replace": ('format = "gonio-reference-certificate/1"', 'format = "x"')},
     "format: must be 'gonio-reference-certificate/1'"),
    ({"replace": ('id = "TEST-42"', 'id = " "')}, "id: must not be empty"),
    ({"replace": ('issuer = "a test"\n', "")}, "missing required key 'issuer'"),
    ({"replace": ("date = 2026-11-30", "date = 5")}, "date: must be a date"),
    ({"quantity": "brdf_x"}, "quantity: must be one of brdf, reflectance_factor"),
    ({"k": 0}, r"coverage_k: must be in \(0, 10\]"),
    ({"header_extra": "colour = 1"}, "unknown key 'colour'"),
    ({"replace": ("value = 0.9\n", "value = -0.9\n")}, r"\[point\[0\]\] value: must be in \(0"),
    ({"replace": ("U = 0.009000000000000001", "U = -1")}, r"\[point\[0\]\] U: must be in \[0"),
    ({"replace": ("theta_o_deg = 80.0", "theta_o_deg = 95.0")}, "theta_o_deg: must be in"),
    ({"drop": 5}, "the points must fill a grid.*none at wavelength_nm 500, theta_i_deg 0, "
                  "theta_o_deg 80, phi_deg 180"),
    ({"extra_point": POINT + "\nvalue = 1.0\nU = 0.0\n"}, r"\[point\[24\]\]: a second point"),
    ({"extra_point": "[[point]]\nwavelength_nm = 500.0\ntheta_i_deg = 0.0\ntheta_o_deg = 0.0"
                     "\nvalue = 1.0\nU = 0.0\n"}, "every point must give the same coordinates"),
    ({"extra_point": POINT + "\nvalue = 1.0\nU = 0.0\nlabel = 1\n"}, "unknown key 'label'"),
    ({"text": 'format = "gonio-reference-certificate/1"\nid = "a"\nissuer = "b"\ndate = "c"\n'
              'quantity = "brdf"\ncoverage_k = 2\n'}, "point: must be a non-empty array"),
])
def test_every_malformed_field_is_one_error_naming_it(tmp_path, change, message):
    change = dict(change)
    text, replace = change.pop("text", None), change.pop("replace", None)
    text = text if text is not None else certificate_text(**change)
    if replace is not None:
        assert replace[0] in text
        text = text.replace(replace[0], replace[1], 1)
    path = write(tmp_path, text)
    with pytest.raises(CalibrationError, match=message) as caught:
        certificate.load(path)
    assert str(path.resolve() if "TOML" not in message else path) in str(caught.value)
    assert "\n" not in str(caught.value)


def test_a_missing_certificate_is_one_error(tmp_path):
    with pytest.raises(CalibrationError, match="cannot read certificate"):
        certificate.load(tmp_path / "none.toml")


def test_relative_azimuth_is_180_on_the_specular_side_and_folded():
    wi = np.array([[-0.5, 0.0, 0.866]] * 3)
    wo = np.array([[0.5, 0.0, 0.866], [-0.5, 0.0, 0.866], [0.0, -0.5, 0.866]])
    np.testing.assert_allclose(relative_azimuth_deg(wi, wo), [180.0, 0.0, 90.0], atol=1e-12)


def reference_data(scale: float, noise: float, solid_rel: float, beam_rel: float,
                   seed: int = 0) -> tuple[ReducedData, certificate.Certificate]:
    """A reference run's absolute reduction: the certificate's BRDF times `scale`, own noise
    `noise` (relative), a solid-angle and a beam error shared by all points."""
    cert = certificate.parse(
        {"format": certificate.FORMAT, "id": "LAMBERT", "issuer": "t", "date": "d",
         "quantity": "reflectance_factor", "coverage_k": 2.0,
         "point": [{"wavelength_nm": 633.0, "theta_i_deg": ti, "theta_o_deg": to,
                    "value": 0.98, "U": 0.0098} for ti in (0.0, 60.0) for to in (0.0, 85.0)]},
        "lambert.toml", "0" * 64)
    theta_o = np.radians(np.arange(-70.0, 71.0, 10.0))
    wo = np.stack([np.sin(theta_o), np.zeros_like(theta_o), np.cos(theta_o)], axis=1)
    wi = np.broadcast_to([-math.sin(0.3), 0.0, math.cos(0.3)], wo.shape).copy()
    f = 0.98 / math.pi * scale * (1 + noise * np.random.default_rng(seed).standard_normal(len(wo)))
    shared = np.tile([solid_rel, beam_rel], (len(f), 1))
    sigma = f * np.sqrt(noise**2 + solid_rel**2 + beam_rel**2)
    components = {"read_noise": f * noise, "solid_angle": f * solid_rel,
                  "beam_normalisation": f * beam_rel}
    data = ReducedData(wi, wo, f, sigma, np.ones(len(f), bool), np.zeros(len(f), bool),
                       {"wavelength_nm": 633.0, "aperture_sr": 3e-4}, shared, None, components)
    return data, cert


def test_the_reference_scale_is_measured_over_certified_without_the_solid_angle_error():
    data, cert = reference_data(scale=1.03, noise=0.01, solid_rel=0.02, beam_rel=0.003)
    ref = scale_from(data, cert, "ref-run")
    n = len(data.bsdf)
    assert ref.points == n
    assert abs(ref.scale.value - 1.03) < 4 * 1.03 * 0.01 / math.sqrt(n)
    assert ref.solid_angle_sr.value == pytest.approx(3e-4 * ref.scale.value)
    # own noise of the mean (scaled by sqrt(chi2/dof) if above 1) and the beam's, not the
    # solid angle's, which the samples' reductions share
    own = 0.01 / math.sqrt(n) * math.sqrt(max(ref.chi2_dof, 1.0))
    assert ref.run_rel == pytest.approx(math.hypot(own, 0.003), rel=1e-3)  # weights vary
    assert ref.certificate_rel == pytest.approx(0.005)
    assert ref.certificate == cert.to_json()


def test_a_reference_run_whose_shape_the_certificate_lacks_shows_in_chi2():
    data, cert = reference_data(scale=1.0, noise=0.001, solid_rel=0.0, beam_rel=0.0)
    tilted = dataclasses.replace(data, bsdf=data.bsdf * (1 + 0.05 * data.wo[:, 0]))
    assert scale_from(data, cert, "r").chi2_dof < 3.0
    assert scale_from(tilted, cert, "r").chi2_dof > 100.0


def test_a_reference_run_outside_the_certificate_or_without_points_is_refused():
    data, cert = reference_data(scale=1.0, noise=0.01, solid_rel=0.0, beam_rel=0.0)
    data.meta["wavelength_nm"] = 800.0
    with pytest.raises(CalibrationError, match="LAMBERT' covers wavelength_nm 633 only"):
        scale_from(data, cert, "r")
    data.meta["wavelength_nm"] = 633.0
    data.valid[:] = False
    with pytest.raises(CalibrationError, match="r: a reference run needs at least two valid"):
        scale_from(data, cert, "r")


def reference_scale(solid_angle_sr: float, wavelength_nm: float = 633.0) -> ReferenceScale:
    return ReferenceScale(
        certificate={"id": "LAMBERT", "sha256": "0" * 64}, run="ref-run",
        wavelength_nm=wavelength_nm, solid_angle_sr=Measured(solid_angle_sr, 1e-3 * solid_angle_sr),
        nominal_solid_angle_sr=solid_angle_sr / 1.02, scale=Measured(1.02, 1e-3),
        certificate_rel=0.004, run_rel=1e-3, points=15, chi2_dof=0.9)


def test_a_calibration_file_records_its_reference_and_reads_it_back(tmp_path):
    cal = Calibration(created_utc="2026-12-08T01:00:00Z", reference=reference_scale(3e-4))
    back = calfile.load(calfile.save(cal, tmp_path / "cal.json"))
    assert back.reference == cal.reference
    assert applied(back, "cal.json")[-1] == ("  reference: LAMBERT at 633 nm, solid angle "
                                             "0.0003 +- 3e-07 sr, certificate u 0.40%")
    assert applied(Calibration(created_utc="x"), "c.json")[-1] == "  reference: none"
    bad = cal.to_json()
    bad["reference"]["certificate_rel"] = "much"
    with pytest.raises(CalibrationError, match=r"x.json: \[reference\] certificate_rel: must "
                                               "be a number"):
        Calibration.from_json(bad, "x.json")


def test_a_reduction_normalised_to_the_reference_carries_its_shared_terms():
    """The same readings reduced absolutely and against a reference whose effective solid
    angle is 2 % above the aperture's: values 2 % lower, the solid angle's term replaced by the
    certificate's and the reference run's, each one error shared by every point."""
    scan = spec_scan(30.0, calibrated=True)
    readings, _ = scan.draw(0)
    run = spec_run(scan)
    cal = scan.calibration()
    optics = optics_of(run.config, cal, run.plan)
    absolute = reduce_readings(run, readings, cal, optics)
    ref = reference_scale(1.02 * optics.aperture_sr)
    relative = reduce_readings(run, readings, dataclasses.replace(cal, reference=ref), optics)
    ok = absolute.valid
    np.testing.assert_allclose(relative.bsdf[ok], absolute.bsdf[ok] / 1.02, rtol=1e-12)
    assert "solid_angle" in absolute.components and "solid_angle" not in relative.components
    shared = relative.meta["budget"]["shared"]
    assert {"reference_certificate", "reference_run"} <= set(shared)
    np.testing.assert_allclose(relative.components["reference_certificate"][ok],
                               0.004 * relative.bsdf[ok])
    assert "LAMBERT" in relative.meta["budget"]["sources"]["reference_certificate"]
    assert relative.meta["reference"]["certificate"]["id"] == "LAMBERT"
    # one column each in the fit's covariance, common to every point
    columns = relative.shared_rel.shape[1] - absolute.shared_rel.shape[1]
    assert columns == 1  # two reference columns in, the solid angle's out
    with pytest.raises(CalibrationError, match="measured at 700 nm and this run at 633 nm"):
        reduce_readings(run, readings, dataclasses.replace(
            cal, reference=reference_scale(3e-4, 700.0)), optics)
