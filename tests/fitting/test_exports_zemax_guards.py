"""The guard blocks of a Zemax file (calibration.exports.zemax.guarded): read from the file's
text by an independent route, each lies 1e-6 deg below a sample rotation or angle of
incidence and holds the linear interpolation between its neighbours; gonio's own reader drops
them again, and a guard comment it cannot follow is one error naming the file."""

import numpy as np
import pytest

from calibration.exports.zemax import ZemaxTable, read_zemax, write_zemax
from calibration.values import CalibrationError


def two_by_two() -> ZemaxTable:
    """Sample rotations 0 and 45, incidences 0 and 19.337122899699327 deg (a refracted angle),
    a 3 x 4 grid whose values differ by orders of magnitude between the blocks."""
    rng = np.random.default_rng(3)
    data = 10.0 ** rng.uniform(-8, 1, size=(2, 2, 3, 4))
    return ZemaxTable("BTDF", "Asymmetrical", np.array([0.0, 45.0]),
                      np.array([0.0, 19.337122899699327]), np.array([0.0, 180.0, 360.0]),
                      np.array([0.0, 1.0, 2.0, 3.0]), data, rng.uniform(0.1, 1.0, (2, 2)),
                      ["a comment"], "Measured")


def file_blocks(path) -> tuple[list[float], list[float], np.ndarray, np.ndarray]:
    """(rotations, incidences, data[rotation, angle, azimuth, radial], tis) as the file's
    text holds them."""
    lines = [ln.strip() for ln in path.read_text().splitlines()
             if ln.strip() and not ln.startswith("#")]
    rotations = [float(v) for v in lines[lines.index("SampleRotation  3") + 1].split()]
    angles = [float(v) for v in lines[lines.index("AngleOfIncidence  3") + 1].split()]
    body = lines[lines.index("DataBegin") + 1:lines.index("DataEnd")]
    tis = np.array([float(ln.split()[1]) for ln in body if ln.startswith("TIS")])
    rows = np.array([[float(v) for v in ln.split()] for ln in body if not ln.startswith("TIS")])
    return (rotations, angles, rows.reshape(len(rotations), len(angles), 3, 4),
            tis.reshape(len(rotations), len(angles)))


def test_guard_blocks_hold_the_interpolation_and_are_read_away(tmp_path):
    table = two_by_two()
    path = write_zemax(table, tmp_path / "guarded.bsdf")
    rotations, angles, data, tis = file_blocks(path)
    assert rotations == [0.0, 44.999999, 45.0]
    assert angles == [0.0, 19.3371219, 19.3371229]
    # the guards in each axis: the linear interpolation at their angle
    s_angle = (angles[2] - angles[1]) / (angles[2] - angles[0])
    s_rotation = (rotations[2] - rotations[1]) / (rotations[2] - rotations[0])
    expected = table.data[:, 1] + s_angle * (table.data[:, 0] - table.data[:, 1])
    np.testing.assert_allclose(data[[0, 2], 1], expected, rtol=1e-9)
    expected = table.data[1] + s_rotation * (table.data[0] - table.data[1])
    np.testing.assert_allclose(data[1, [0, 2]], expected, rtol=1e-9)
    np.testing.assert_array_equal(data[[0, 2]][:, [0, 2]], table.data)
    np.testing.assert_array_equal(tis[[0, 2]][:, [0, 2]], table.tis)
    back = read_zemax(path)
    np.testing.assert_array_equal(back.sample_rotation_deg, [0.0, 45.0])
    np.testing.assert_array_equal(back.angle_deg, [0.0, 19.3371229])
    np.testing.assert_array_equal(back.data, table.data)
    np.testing.assert_array_equal(back.tis, table.tis)
    assert back.comments == ["a comment"]


def test_one_block_has_no_guard(tmp_path):
    table = two_by_two()
    one = ZemaxTable("BTDF", "Asymmetrical", table.sample_rotation_deg[:1], table.angle_deg[:1],
                     table.azimuth_deg, table.radial_deg, table.data[:1, :1],
                     table.tis[:1, :1], [])
    text = write_zemax(one, tmp_path / "one.bsdf").read_text()
    assert "guard" not in text and "SampleRotation  1\n0.0\nAngleOfIncidence  1\n0.0\n" in text


def test_a_guard_comment_it_cannot_follow_names_the_file(tmp_path):
    path = write_zemax(two_by_two(), tmp_path / "guarded.bsdf")
    text = path.read_text().replace("AngleOfIncidence 19.3371219 (", "Angle 19.33 (")
    path.write_text(text)
    with pytest.raises(CalibrationError, match=r"guarded\.bsdf: the comment 'guard blocks:"
                                               r".*does not name the guard blocks"):
        read_zemax(path)
