"""Plain CSV tables of one incidence (columns theta_o[, phi_o], value[, sigma]): theta_i from
--incidence-deg or a header line, signed in-plane theta_o without phi_o, and one clear error for
each malformed table."""

import math

import numpy as np
import pytest

from calibration.formats.file_format import ImportOptions
from calibration.imports import read_measured
from calibration.values import CalibrationError
from gonio_cli.main import main

TABLE = "theta_o_deg,value,sigma\n-40,0.10,0.002\n0,0.11,0.002\n30,0.50,0.01\n60,0.12,0.002\n"


def test_a_header_line_gives_the_incidence_and_theta_o_is_signed(tmp_path):
    path = tmp_path / "t.csv"
    path.write_text("# theta_i_deg: 30\n# eta: 1.5\n" + TABLE)
    data = read_measured(path)
    assert np.allclose(data.theta_i_deg, 30.0)
    assert np.allclose(data.theta_o_deg, [-40, 0, 30, 60])  # as gonio signs it: + forward
    wi = np.array([math.sin(math.radians(30)), 0.0, math.cos(math.radians(30))])
    assert np.allclose(data.wi, wi)
    mirror = wi * [-1, -1, 1]
    assert np.allclose(data.wo[2], mirror)  # +30 is the specular direction
    assert data.wo[0, 0] > 0  # -40: on the source's side
    assert np.allclose(data.bsdf, [0.10, 0.11, 0.50, 0.12]) and not data.transmission.any()


def test_the_option_gives_the_incidence_and_phi_o_places_the_points(tmp_path):
    path = tmp_path / "t.csv"
    path.write_text("theta_o,phi_o,value\n10,180,0.2\n20,0,0.1\n")
    data = read_measured(path, ImportOptions(eta=1.5, sigma_relative=0.05, incidence_deg=45.0))
    assert np.allclose(data.theta_i_deg, 45.0) and np.allclose(data.theta_o_deg, [10, -20])
    assert np.allclose(data.sigma, [0.01, 0.005])


@pytest.mark.parametrize("text, options, message", [
    (TABLE, ImportOptions(eta=1.5), "a table without a theta_i column is one of a single "
     "incidence: give --incidence-deg DEG or a header line `# theta_i_deg: DEG`"),
    ("# theta_i_deg: 30\n" + TABLE, ImportOptions(eta=1.5, incidence_deg=30.0),
     "the incidence is given twice"),
    (TABLE, ImportOptions(eta=1.5, incidence_deg=95.0),
     "the incidence must be a number of degrees in [0, 90), got 95.0"),
    ('# theta_i_deg: "thirty"\n' + TABLE, ImportOptions(eta=1.5),
     "the incidence must be a number of degrees in [0, 90), got 'thirty'"),
    ("theta_o,value,sigma\n95,0.1,0.01\n10,0.1,0.01\n", ImportOptions(eta=1.5, incidence_deg=0.0),
     "theta_o without a phi_o column is the signed in-plane angle and must lie within (-90, 90)"),
    ("theta_o,sigma\n10,0.1\n", ImportOptions(eta=1.5, incidence_deg=0.0), "no column bsdf"),
    ("value,sigma\n0.1,0.01\n", ImportOptions(eta=1.5, incidence_deg=0.0), "no column theta_o"),
    ("theta_o,value,sigma\n10,abc,0.01\n", ImportOptions(eta=1.5, incidence_deg=0.0),
     "data row 1: column bsdf is not a number"),
    ("theta_i,phi_i,theta_o,phi_o,bsdf,sigma\n0,0,10,0,0.1,0.01\n",
     ImportOptions(eta=1.5, incidence_deg=0.0), "the table has a theta_i column"),
])
def test_a_malformed_table_is_one_error(tmp_path, text, options, message):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(CalibrationError) as caught:
        read_measured(path, options)
    assert message in str(caught.value) and str(caught.value).startswith(str(path))


def test_gonio_reduce_imports_a_table_of_one_incidence(tmp_path, capsys):
    path = tmp_path / "t.csv"
    path.write_text("# eta: 1.5\n" + TABLE)
    assert main(["reduce", "--import", str(path), "--incidence-deg", "30",
                 "--out", str(tmp_path / "r.csv")]) == 0
    assert capsys.readouterr().out.startswith(f"imported {path}: eta 1.5,")
    assert main(["reduce", "--import", str(path), "--out", str(tmp_path / "r.csv")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "give --incidence-deg DEG" in err
