"""Issue 34: URScript targets as programs hold them. Poses relative to a feature
(``pose_trans(Plane_1, ..)``), pose variables of any scope, a TCP from a variable, every
move counted and what cannot be known left with its reason. Checked through the stand-in
nominal controller of the Cartesian tests: the calibrated robot reaches the taught poses."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from kinecal.compensation._cartesian import calibrated_flange
from kinecal.io._cartesian_programs import read_cartesian
from tests.compensation.test_issue_34_cartesian import (
    T_TOOL,
    _controller,
    _numbers,
    _pose,
    _read_pose,
    _taught,
)

_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
T_PLANE = _pose([0.42, 0.15, 0.05], [0.0, 0.0, 0.7])  # a Polyscope plane feature


@pytest.fixture
def run_cli(run_cli_here):
    return run_cli_here


@pytest.fixture(scope="module")
def model_file(tracker_twin, tmp_path_factory):
    from kinecal.io import save_model

    return save_model(
        tmp_path_factory.mktemp("ur34") / "model.yaml", tracker_twin.calibrated
    )


def _p(T) -> str:
    return "p[" + ", ".join(f"{x:.9f}" for x in _numbers("urscript", T)) + "]"


def _script(T_feat_targets, T_base_targets, q) -> str:
    """The targets, each after a joint move to its taught joints (the controller
    starts a Cartesian move from where the arm is)."""
    a, b = T_feat_targets
    c, d = T_base_targets
    j = ["  movej([" + ", ".join(f"{x:.9f}" for x in qq) + "])" for qq in q]
    return "\n".join(
        [
            "def prog():",
            f"  global Plane_1={_p(T_PLANE)}",
            f"  global my_tcp={_p(T_TOOL)}",
            "  set_tcp(my_tcp)",
            j[0],
            f"  movel(pose_trans(Plane_1, {_p(a)}), a=1.2, v=0.25)",
            f"  local approach = {_p(b)}",
            j[1],
            "  movel(pose_trans(Plane_1, approach), a=1.2, v=0.25)",
            "  movel(pose_trans(Plane_1, approach), a=1.2, v=0.1)",
            f"  pick = {_p(c)}",
            j[2],
            "  movej(pick, a=1.4, v=1.05)",
            j[3],
            f"  movel({_p(d)}, a=1.2, v=0.25)",
            "  movel(pose_add(pick, p[0, 0, 0.05, 0, 0, 0]), a=1.2, v=0.25)",
            "  movel(get_target_tcp_pose(), a=1.2, v=0.25)",
            "  movel(unknown_pose, a=1.2, v=0.25)",
            "end",
            "",
        ]
    )


def test_issue_34_urscript_features_and_variables(
    tracker_twin, model_file, run_cli, tmp_path
):
    cal = tracker_twin.calibrated
    robot = cal.model.robot
    q = _taught(np.random.default_rng(343), 4)
    F = robot.fk_flange(q) @ T_TOOL  # taught tool poses in the base frame
    feat = np.linalg.inv(T_PLANE) @ F[:2]
    src = tmp_path / "prog.script"
    src.write_text(_script(feat, F[2:], q))
    res = run_cli(
        "compensate", src, "--model", model_file, "--out", tmp_path / "out.script",
        "--json",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    summary = json.loads(res.stdout.strip().splitlines()[-1])
    # 4 targets corrected (approach once though used twice), 4 joint moves; 3 moves
    # left, named.
    assert summary["ok"] == 8 and summary["left"] == 3, res.stderr
    assert "7 Cartesian targets: 4 corrected, 3 left" in res.stderr
    assert "a computed target (pose_add(pick" in res.stderr
    assert "a computed target (get_target_tcp_pose()" in res.stderr
    assert "unknown_pose: not assigned a pose p[..]" in res.stderr
    text = (tmp_path / "out.script").read_text()
    pts = [p for p in read_cartesian(text, "urscript") if p.values]
    assert [p.name for p in pts] == ["movel", "approach", "pick", "movel"]
    # the feature and the TCP themselves are not targets: unchanged
    assert f"global Plane_1={_p(T_PLANE)}" in text and f"my_tcp={_p(T_TOOL)}" in text
    frames = [T_PLANE, T_PLANE, np.eye(4), np.eye(4)]
    for k, (pt, T_f) in enumerate(zip(pts, frames, strict=True)):
        T_new = _read_pose("urscript", pt.values)
        q_c = _controller(robot, T_f @ T_new @ np.linalg.inv(T_TOOL), q[k])
        got = calibrated_flange(cal, q_c[None])[0] @ T_TOOL
        assert np.linalg.norm(got[:3, 3] - F[k][:3, 3]) * 1e3 < 0.01, k
        old = [float(x) for x in re.findall(_NUM, _p(feat[k] if k < 2 else F[k]))]
        assert np.abs(np.subtract(pt.values[:3], old[:3])).max() > 1e-4  # moved


def test_issue_34_urscript_ambiguous_variables_left():
    text = "\n".join(
        [
            "def p():",
            "  set_tcp(p[0, 0, 0.1, 0, 0, 0])",
            "  w = p[0.4, 0.1, 0.3, 0, 3.14, 0]",
            "  movel(w)",
            "  movel(pose_trans(p[0.1, 0, 0, 0, 0, 0.5], w))",  # w in two frames
            "  v = p[0.4, 0.1, 0.3, 0, 3.14, 0]",
            "  v = p[0.5, 0.1, 0.3, 0, 3.14, 0]",  # assigned twice
            "  movel(v)",
            "  set_tcp(tcp_of_the_day)",  # an unknown tool
            "  movel(p[0.4, 0.2, 0.3, 0, 3.14, 0])",
            "  movej([0, -1.57, 1.57, 0, 1.57, 0])",  # a joint target: not here
            "end",
        ]
    )
    got = {(p.line, p.why_not.split(":")[0]) for p in read_cartesian(text, "urscript")}
    assert got == {
        (3, "used in different frames or with different tools"),
        (8, "v"),
        (10, "set_tcp"),
    }, got


def test_issue_34_urscript_polyscope_movej_and_joint_variables():
    """Polyscope's MoveJ to a waypoint, movej(get_inverse_kin(Waypoint_1_p, qnear=..)),
    is a move to Waypoint_1_p (it was left uncounted, and the waypoint uncorrected); a
    move to a joint-list variable is a joint target at its assignment."""
    text = "\n".join(
        [
            "def prog():",
            "  global Waypoint_1_p=p[0.4, 0.1, 0.3, 0.0, 3.1, 0.0]",
            "  global Waypoint_1_q=[0.1, -1.2, 1.5, -1.8, -1.6, 0.0]",
            "  movej(get_inverse_kin(Waypoint_1_p, qnear=Waypoint_1_q), a=1.39, v=1.04)",
            "  q_home = [0.0, -1.57, 1.2, -1.57, -1.57, 0.0]",
            "  movej(q_home, a=1.0, v=0.5)",
            "end",
        ]
    )
    cart = read_cartesian(text, "urscript")
    assert [(p.name, p.line, p.why_not) for p in cart] == [("Waypoint_1_p", 2, "")]
    assert cart[0].q_values == (0.1, -1.2, 1.5, -1.8, -1.6, 0.0)


def test_issue_34_urscript_joint_variable_is_a_joint_target(tmp_path):
    from kinecal.io import read_program

    f = tmp_path / "p.script"
    f.write_text("def p():\n  q_home = [0.0, -1.57, 1.2, -1.57, -1.57, 0.0]\n"
                 "  movej(q_home, a=1.0, v=0.5)\n  movej(q_home)\nend\n")  # fmt: skip
    prog = read_program(f)
    assert [(p.name, p.line) for p in prog.points] == [("q_home", 2)]
    assert read_cartesian(f.read_text(), "urscript") == []
