"""Issue 34, second round: URScript targets relative to features (``pose_trans(Plane_1,
...)``) and pose variables assigned anywhere (``name = p[...]``, ``global``, ``local``);
RAPID moves to ``Offs(p10, ...)`` / ``RelTool(p10, ...)``. Every target counted; the
corrected ones reached through the stand-in nominal controller of
test_issue_34_cartesian within 0.01 mm."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from kinecal.compensation._cartesian import calibrated_flange
from kinecal.io import save_model
from tests.compensation.test_issue_34_cartesian import (
    T_TOOL,
    T_UF,
    _controller,
    _numbers,
    _read_pose,
    _taught,
)

_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"


@pytest.fixture
def run_cli(run_cli_here):
    return run_cli_here


@pytest.fixture(scope="module")
def model_file(tracker_twin, tmp_path_factory):
    return save_model(
        tmp_path_factory.mktemp("p34u") / "model.yaml", tracker_twin.calibrated
    )


def _ur(T):
    return "p[" + ", ".join(f"{x:.9f}" for x in _numbers("urscript", T)) + "]"


def _near(rng, q0, n):
    """Taught joints within 8 deg of q0 (one IK branch from the movej before)."""
    return q0 + np.radians(rng.uniform(-8, 8, (n, 6)))


def test_issue_34_urscript_features_and_pose_variables(
    tracker_twin, model_file, run_cli, tmp_path
):
    cal = tracker_twin.calibrated
    robot = cal.model.robot
    rng = np.random.default_rng(341)
    q0 = _taught(rng, 1)[0]
    q = _near(rng, q0, 5)
    F = robot.fk_flange(q)
    T_base = F @ T_TOOL  # tool poses in the base frame
    T_feat = np.linalg.inv(T_UF) @ T_base  # ... in the feature Plane_1 (= T_UF)
    lines = [
        "def prog():",
        f"  set_tcp({_ur(T_TOOL)})",
        f"  global Plane_1={_ur(T_UF)}",
        f"  movej([{', '.join(f'{v:.6f}' for v in q0)}], a=1.4, v=1.05)",
        f"  global Waypoint_1_p={_ur(T_base[0])}",  # 5: base frame, Polyscope
        "  movel(Waypoint_1_p, a=1.2, v=0.25)",
        f"  Approach = {_ur(T_feat[1])}",  # 7: feature-relative variable
        "  movel(pose_trans(Plane_1, Approach), a=1.2, v=0.25)",
        f"  local Pick = {_ur(T_feat[2])}",  # 9: local, through get_inverse_kin
        "  movej(get_inverse_kin(pose_trans(Plane_1, Pick)), a=1.4, v=1.05)",
        f"  movel(pose_trans(Plane_1, {_ur(T_feat[3])}), a=1.2, v=0.25)",  # 11: inline
        f"  movel(pose_trans(Table_2, {_ur(T_feat[4])}), a=1.2, v=0.25)",  # 12: unknown
        f"  Both = {_ur(T_base[4])}",  # 13: also in an expression
        "  movel(Both, a=1.2, v=0.25)",
        "  movel(pose_add(Both, p[0, 0, 0.05, 0, 0, 0]), a=1.2, v=0.25)",
        f"  Lifted = {_ur(T_base[4])}",  # 16: reassigned from an expression
        "  Lifted = get_actual_tcp_pose()",
        "  movel(Lifted, a=1.2, v=0.25)",
        "  offset = p[0, 0, 0.1, 0, 0, 0]",  # no move goes to it: not a target
        "end",
    ]
    src, out = tmp_path / "f.script", tmp_path / "c.script"
    src.write_text("\n".join([*lines, ""]))
    res = run_cli(
        "compensate", str(src), "--model", str(model_file), "--out", str(out), "--json"
    )
    assert res.returncode == 0, res.stderr
    summary = json.loads(res.stdout.strip().splitlines()[-1])
    # 1 joint target + 7 Cartesian: Waypoint_1_p, Approach, Pick, inline, Table_2,
    # Both, Lifted (offset is no target).
    assert summary["n"] == 8 and summary["ok"] == 5 and summary["left"] == 3, res.stderr
    assert "7 Cartesian targets: 4 corrected, 3 left as written" in res.stderr
    assert (
        "line 12 (movel): left as written: feature Table_2: its pose is not"
        in res.stderr
    )
    assert (
        "line 13 (Both): left as written: a move uses it in an expression (line 15)"
        in res.stderr
    )
    assert (
        "line 16 (Lifted): left as written: it is also assigned from an expression"
        in res.stderr
    )
    text = out.read_text().splitlines()
    for k, (ln, T_uf) in enumerate([(5, np.eye(4)), (7, T_UF), (9, T_UF), (11, T_UF)]):
        vals = [
            float(v)
            for v in re.search(r"p\[([^\]]*)\]", text[ln - 1]).group(1).split(",")
        ]
        T_new = _read_pose("urscript", vals)
        q_ctrl = _controller(robot, T_uf @ T_new @ np.linalg.inv(T_TOOL), q[k])
        got = calibrated_flange(cal, q_ctrl[None])[0] @ T_TOOL
        assert np.linalg.norm(got[:3, 3] - T_base[k][:3, 3]) * 1e3 < 0.01, k
        assert (
            np.linalg.norm(T_new[:3, 3] - (np.linalg.inv(T_uf) @ T_base[k])[:3, 3])
            > 1e-4
        )
    for ln in (12, 13, 16, 19):
        assert text[ln - 1] == lines[ln - 1]
    # The feature given on the command line: Table_2 is corrected too.
    table = "Table_2=" + _ur(T_UF)[2:-1].replace(" ", "")
    res = run_cli(
        "compensate", str(src), "--model", str(model_file), "--out",
        str(tmp_path / "d.script"), "--json", "--uframe", table,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert json.loads(res.stdout.strip().splitlines()[-1])["ok"] == 6
