"""Measurement and target CSVs: every bad input names file, line and column."""

from __future__ import annotations

import numpy as np
import pytest

from kinecal.errors import DataError
from kinecal.identification import Measurements
from kinecal.io import (
    measurements_to_csv,
    read_measurements,
    read_targets,
    write_targets,
)
from kinecal.robot import load_robot

ROBOT = load_robot("fanuc-lrmate200id")
HEAD = "j1_deg,j2_deg,j3_deg,j4_deg,j5_deg,j6_deg,x_mm,y_mm,z_mm"


def _rows(n=6):
    rng = np.random.default_rng(0)
    out = []
    for _ in range(n):
        q = rng.uniform(-60, 60, 6)
        p = rng.uniform(-800, 800, 3)
        out.append(",".join(f"{v:.4f}" for v in (*q, *p)))
    return out


def _write(tmp_path, text, name="data.csv"):
    f = tmp_path / name
    f.write_text(text)
    return f


def test_good_point_file(tmp_path):
    f = _write(tmp_path, "# a comment\n" + HEAD + "\n" + "\n".join(_rows()) + "\n")
    m = read_measurements(f, ROBOT)
    assert m.kind == "point" and m.n == 6
    assert np.abs(m.q_ctrl).max() < np.radians(61)
    assert m.rows[0] == 3  # file line of the first data row


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("", r"data.csv: the file is empty"),
        (HEAD + "\n", r"data.csv: no data rows"),
        (HEAD.replace(",z_mm", "") + "\n1,2,3,4,5,6,7,8\n", r"missing column 'z_mm'"),
        (
            HEAD + "\n" + "1,2,3,4,5,6,7,nan,9\n",
            r"line 2, column 'y_mm': expected a finite number; got 'nan'",
        ),
        (
            HEAD + "\n" + "1,2,3,4,5,6,7,abc,9\n",
            r"line 2, column 'y_mm': expected a number; got 'abc'",
        ),
        (HEAD + "\n" + "1,2,3,4,5,6,7,8\n", r"line 2: 8 values for 9 columns"),
        (
            HEAD.replace("j6_deg", "j7_deg") + "\n" + "1,2,3,4,5,6,7,8,9\n",
            r"robot fanuc-lrmate200id has 6 joints",
        ),
        ("j1_deg,j2_deg,x_mm,y_mm,z_mm\n1,2,3,4,5\n", r"has 6 joints"),
        (HEAD + ",j7_deg\n" + "1,2,3,4,5,6,7,8,9,1\n", r"has 6 joints"),
        ("x_mm,y_mm,z_mm\n1,2,3\n", r"no joint columns"),
        (
            HEAD + ",sigma\n" + "1,2,3,4,5,6,700,800,900,1\n",
            r"column 'sigma' is not understood",
        ),
        (
            HEAD + ",sigma_mm\n" + "1,2,3,4,5,6,700,800,900,0\n",
            r"line 2, column 'sigma_mm': 0; expected a positive standard deviation in mm",
        ),
        (
            HEAD + ",payload_kg\n" + "1,2,3,4,5,6,700,800,900,-0.5\n",
            r"line 2, column 'payload_kg': -0.5; expected a mass in kg, 0 or more .*0: "
            r"no payload",
        ),
        (HEAD + ",x_mm\n" + "1,2,3,4,5,6,7,8,9,1\n", r"duplicate column 'x_mm'"),
    ],
)
def test_bad_files(tmp_path, text, match):
    f = _write(tmp_path, text)
    with pytest.raises(DataError, match=match) as info:
        read_measurements(f, ROBOT)
    assert str(info.value).startswith(str(f))
    assert "\n" not in str(info.value)


def test_radians_in_degree_columns(tmp_path):
    rng = np.random.default_rng(1)
    lines = [HEAD]
    for _ in range(20):
        q = rng.uniform(-1.5, 1.5, 6)  # radians, by mistake
        lines.append(",".join(f"{v:.5f}" for v in (*q, 400.0, 100.0, 300.0)))
    f = _write(tmp_path, "\n".join(lines) + "\n")
    with pytest.raises(
        DataError,
        match=r"looks like radians; convert to degrees or name the columns jK_rad",
    ):
        read_measurements(f, ROBOT)
    g = _write(tmp_path, "\n".join(lines).replace("_deg", "_rad") + "\n", "rad.csv")
    assert read_measurements(g, ROBOT).n == 20  # declared radians are fine


def test_metres_in_millimetre_columns(tmp_path):
    lines = [HEAD] + [f"{i},0,0,0,{i},0,0.4{i},0.1,0.3" for i in range(10)]
    f = _write(tmp_path, "\n".join(lines) + "\n")
    with pytest.raises(DataError, match="looks like metres"):
        read_measurements(f, ROBOT)


def test_pose_and_quaternion_checks(tmp_path):
    head = HEAD + ",qw,qx,qy,qz"
    f = _write(tmp_path, head + "\n" + "1,2,3,4,5,6,700,800,900,1,0,0,0\n")
    m = read_measurements(f, ROBOT)
    assert m.kind == "pose"
    np.testing.assert_allclose(m.R_user_cam[0], np.eye(3))
    f = _write(tmp_path, head + "\n" + "1,2,3,4,5,6,700,800,900,0.5,0,0,0\n", "bad.csv")
    with pytest.raises(
        DataError, match=r"line 2, columns qw..qz: quaternion norm 0.5000"
    ):
        read_measurements(f, ROBOT)


def test_pose_as_fanuc_wpr_matches_scipy_xyz_euler(tmp_path):
    """W, P, R columns are roll, pitch, yaw about the fixed x, y, z axes."""
    from scipy.spatial.transform import Rotation

    wpr = np.array([[10.0, -20.0, 30.0], [-170.0, 45.0, 95.0]])
    lines = [f"1,2,3,4,5,6,700,800,900,{w},{p},{r}" for w, p, r in wpr]
    f = _write(tmp_path, HEAD + ",w_deg,p_deg,r_deg\n" + "\n".join(lines) + "\n")
    m = read_measurements(f, ROBOT)
    assert m.kind == "pose"
    want = Rotation.from_euler("xyz", wpr, degrees=True).as_matrix()
    np.testing.assert_allclose(m.R_user_cam, want, atol=1e-12)
    both = _write(
        tmp_path,
        HEAD + ",qw,qx,qy,qz,w_deg,p_deg,r_deg\n1,2,3,4,5,6,7,8,9,1,0,0,0,0,0,0\n",
        "both.csv",
    )
    with pytest.raises(DataError, match=r"either as qw\.\.qz or as w_deg"):
        read_measurements(both, ROBOT)
    part = _write(tmp_path, HEAD + ",w_deg,p_deg\n1,2,3,4,5,6,7,8,9,0,0\n", "part.csv")
    with pytest.raises(DataError, match="missing column 'r_deg'"):
        read_measurements(part, ROBOT)


def test_sensor_data_and_targets(tmp_path):
    t = _write(
        tmp_path,
        "target,x_mm,y_mm,z_mm,r_mm\nS1,185.3,408.4,2303.9,15\nS2,240.4,377.9,2640.9,15\n",
        "t.csv",
    )
    head = "target,j1_deg,j2_deg,j3_deg,j4_deg,j5_deg,j6_deg,xc_mm,yc_mm,zc_mm"
    f = _write(tmp_path, head + "\nS2,1,2,3,4,5,6,1,2,125\nS1,1,2,3,4,5,6,1,2,120\n")
    m = read_measurements(f, ROBOT, t)
    assert m.kind == "sensor" and list(m.target_index) == [1, 0]
    np.testing.assert_allclose(m.targets[1], [0.2404, 0.3779, 2.6409])
    with pytest.raises(DataError, match="needs a --targets file"):
        read_measurements(f, ROBOT)
    g = _write(tmp_path, head + "\nS9,1,2,3,4,5,6,1,2,125\n", "g.csv")
    with pytest.raises(
        DataError, match=r"line 2, column 'target': 'S9' is not in the targets file"
    ):
        read_measurements(g, ROBOT, t)
    u = _write(tmp_path, "target,x_mm,y_mm\nS1,1,2\n", "u.csv")
    with pytest.raises(DataError, match="missing column 'z_mm'"):
        read_targets(u)


def test_round_trip_with_sets_markers_and_weights(tmp_path, rng):
    n = 12
    q = rng.uniform(-1, 1, (n, 6))
    m = Measurements(
        "pose",
        q,
        rng.uniform(-1, 1, (n, 3)),
        R_user_cam=ROBOT.fk_flange(q)[:, :3, :3],  # turning as the robot turns
        set_index=rng.integers(0, 2, n),
        set_labels=("a", "b"),
        marker_index=rng.integers(0, 2, n),
        marker_labels=("m1", "m2"),
        sigma=np.full(n, 2e-5),
        sigma_rot=np.full(n, 1e-4),
        payload_kg=np.full(n, 2.0),
    )
    f = _write(tmp_path, measurements_to_csv(m, ROBOT))
    back = read_measurements(f, ROBOT)
    np.testing.assert_allclose(back.q_ctrl, m.q_ctrl, atol=1e-9)
    np.testing.assert_allclose(back.p, m.p, atol=1e-9)
    assert back.set_labels == ("a", "b") or back.set_labels == ("b", "a")
    assert [back.set_labels[i] for i in back.set_index] == [
        m.set_labels[i] for i in m.set_index
    ]
    np.testing.assert_allclose(back.sigma, 2e-5)
    np.testing.assert_allclose(back.sigma_rot, 1e-4)
    np.testing.assert_allclose(back.payload_kg, 2.0)
    write_targets(
        tmp_path / "t.csv",
        ("A", "B"),
        np.array([[0.1, 0.2, 0.3], [1, 2, 3.0]]),
        np.array([0.015, 0.015]),
    )
    t = read_targets(tmp_path / "t.csv")
    assert t.labels == ("A", "B") and t.radius is not None
