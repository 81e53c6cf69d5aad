"""Issue 38 point 2: the ISO 9283 cube and its test points are where the standard puts
them, and the test program's joints reach them (nominal FK, independent of the IK)."""

from __future__ import annotations

import numpy as np
import pytest

from kinecal.errors import DataError
from kinecal.iso9283 import (
    PLANES,
    VISIT_ORDER,
    iso_cube,
    nominal_model,
    place_cube,
    plan_iso9283,
)
from kinecal.robot import load_robot
from tests.cli_contract import failed_with, run_kinecal

ROBOT = "fanuc-lrmate200id"
TOOL_DOWN = np.diag([1.0, -1.0, -1.0])  # the default test orientation


@pytest.mark.parametrize("plane", list(PLANES))
def test_issue_38_test_points_are_where_the_standard_puts_them(plane):
    centre, a = np.array([0.4, -0.1, 0.2]), 0.3
    cube = iso_cube(centre, a, plane)
    C = cube.corners
    # edges parallel to the base frame: the corners are the centre +- a/2 on each axis
    np.testing.assert_allclose(np.sort(np.unique(C[:, 0])), centre[0] + [-a / 2, a / 2])
    np.testing.assert_allclose(np.sort(np.unique(C[:, 2])), centre[2] + [-a / 2, a / 2])
    # C5..C8 above C1..C4; C1..C4 around the bottom face
    np.testing.assert_allclose(C[4:, :2], C[:4, :2])
    assert np.all(C[4:, 2] > C[:4, 2])
    edges = np.linalg.norm(np.diff(C[[0, 1, 2, 3, 0]], axis=0), axis=1)
    np.testing.assert_allclose(edges, a)
    P = cube.points
    np.testing.assert_allclose(P[0], centre)  # P1: the cube's centre
    k = [int(c[1:]) - 1 for c in plane.split("-")]  # the plane's corners
    Cp = C[k]
    # the four corners are coplanar, a bottom edge and the opposite top edge
    n = np.cross(Cp[1] - Cp[0], Cp[2] - Cp[0])
    assert abs(np.dot(n, Cp[3] - Cp[0])) < 1e-15
    diag = np.sqrt(3.0) * a
    for j in range(4):  # P2..P5 on the diagonals, 10 % of its length from the corner
        corner, far = Cp[j], Cp[(j + 2) % 4]
        assert np.linalg.norm(far - corner) == pytest.approx(diag)
        assert np.linalg.norm(P[j + 1] - corner) == pytest.approx(0.1 * diag)
        assert np.linalg.norm(P[j + 1] - far) == pytest.approx(0.9 * diag)
        assert abs(np.dot(n, P[j + 1] - Cp[0])) < 1e-15  # in the test plane


def test_issue_38_program_reaches_the_points_in_the_standards_order():
    robot = load_robot(ROBOT)
    pl = plan_iso9283(robot, edge=0.2, centre=[0.35, 0.0, 0.25], cycles=3)
    assert pl.q_ctrl.shape == (15, 6)
    assert pl.labels[:5] == VISIT_ORDER == ("P1", "P5", "P4", "P3", "P2")
    assert pl.labels == VISIT_ORDER * 3
    assert pl.cycle.tolist() == [1] * 5 + [2] * 5 + [3] * 5
    T = robot.fk_tool(pl.q_ctrl)  # the robot's own FK, not the model's
    np.testing.assert_allclose(T[:, :3, 3], pl.p_command, atol=1e-9)
    np.testing.assert_allclose(
        T[:, :3, :3], np.broadcast_to(TOOL_DOWN, (15, 3, 3)), atol=1e-8
    )
    lim = robot.limits
    assert np.all((pl.q_ctrl >= lim[:, 0]) & (pl.q_ctrl <= lim[:, 1]))
    # one IK branch: the wrist does not flip between the points
    assert np.ptp(np.degrees(pl.q_points[:, 3])) < 90.0


def test_issue_38_searched_cube_is_the_largest_reachable_at_its_centre():
    robot = load_robot(ROBOT)
    model, x = nominal_model(robot)
    centre = [0.35, 0.0, 0.2]
    cube = place_cube(model, x, TOOL_DOWN, centre=centre)
    assert 0.1 < cube.edge < 0.6
    place_cube(model, x, TOOL_DOWN, centre=centre, edge=cube.edge)  # reachable
    with pytest.raises(DataError, match="not reachable at the given centre"):
        place_cube(model, x, TOOL_DOWN, centre=centre, edge=cube.edge * 1.05)


def test_issue_38_plan_iso9283_cli_writes_the_program(capsys, tmp_path):
    out = tmp_path / "iso.csv"
    res = run_kinecal(
        capsys, "plan", "--iso9283", "--robot", ROBOT, "--cube-mm", "200",
        "--cube-centre", "350,0,250", "--cycles", "30", "--out", out, "-q",
    )  # fmt: skip
    assert res.code == 0, str(res)
    assert "P1 -> P5 -> P4 -> P3 -> P2" in res.out
    from kinecal.io import read_table

    t = read_table(out)
    assert t.header[:6] == [f"j{k}_deg" for k in range(1, 7)]
    assert t.header[6:] == ["iso_point", "iso_cycle", "cmd_x_mm", "cmd_y_mm",
                            "cmd_z_mm", "cmd_a_deg", "cmd_b_deg", "cmd_c_deg"]  # fmt: skip
    assert len(t.rows) == 150
    q = np.radians(np.column_stack([t.numbers(f"j{k}_deg") for k in range(1, 7)]))
    cmd = np.column_stack([t.numbers(f"cmd_{a}_mm") for a in "xyz"])
    T = load_robot(ROBOT).fk_tool(q)
    np.testing.assert_allclose(T[:, :3, 3] * 1e3, cmd, atol=1e-3)
    np.testing.assert_allclose(cmd[0], [350.0, 0.0, 250.0], atol=1e-3)
    rep = (tmp_path / "iso.report.json").read_text()
    assert '"edge_mm": 200.0' in rep and '"C1-C2-C7-C8"' in rep
    # never overwritten without --force
    res = run_kinecal(capsys, "plan", "--iso9283", "--robot", ROBOT, "--out", out)
    failed_with(res, "exists; use --force")


def test_issue_38_plan_iso9283_bad_input(capsys, tmp_path):
    out = tmp_path / "iso.csv"
    res = run_kinecal(
        capsys, "plan", "--iso9283", "--robot", ROBOT, "--cube-mm", "2000",
        "--cube-centre", "350,0,250", "--out", out,
    )  # fmt: skip
    failed_with(res, "edge 2000 mm is not reachable at the given centre", "--cube-mm")
    res = run_kinecal(
        capsys, "plan", "--iso9283", "--robot", ROBOT, "--poses", "10", "--out", out
    )
    failed_with(res, "--iso9283 writes the standard's test poses", "--poses")
    res = run_kinecal(
        capsys, "plan", "--iso9283", "--robot", ROBOT, "--cube-centre", "1,2",
        "--out", out,
    )  # fmt: skip
    failed_with(res, "--cube-centre", "expected 3 comma-separated numbers")
    assert not out.exists()


def test_issue_38_plan_iso9283_points_are_for_the_given_tool(capsys, tmp_path):
    out = tmp_path / "iso.csv"
    res = run_kinecal(
        capsys, "plan", "--iso9283", "--robot", ROBOT, "--cube-mm", "150",
        "--cube-centre", "380,0,200", "--cycles", "2", "--tool", "0,20,120",
        "--orientation", "0,0,180", "--out", out, "-q",
    )  # fmt: skip
    assert res.code == 0, str(res)
    from kinecal.io import read_table

    t = read_table(out)
    q = np.radians(np.column_stack([t.numbers(f"j{k}_deg") for k in range(1, 7)]))
    T_tool = np.eye(4)
    T_tool[:3, 3] = [0.0, 0.02, 0.12]
    T = load_robot(ROBOT).fk_flange(q) @ T_tool
    cmd = np.column_stack([t.numbers(f"cmd_{a}_mm") for a in "xyz"])
    np.testing.assert_allclose(T[:, :3, 3] * 1e3, cmd, atol=1e-3)
    np.testing.assert_allclose(
        T[:, :3, :3], np.broadcast_to(TOOL_DOWN, (10, 3, 3)), atol=1e-7
    )
