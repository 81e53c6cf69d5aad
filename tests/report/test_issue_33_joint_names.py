"""Issue 33: the report's parameter tables show the robot's joint names beside the
parameter names where the robot has them (display only: the names stay model.yaml's
keys); a robot with the default names J1..Jn shows none."""

from __future__ import annotations

from kinecal.report._tables import name_cell
from kinecal.workflows._compare import _shown
from tests.independent_arm import UR6, urdf_text


def test_report_tables_show_joint_names(tmp_path, run_cli_here):
    urdf = tmp_path / "ur6.urdf"
    urdf.write_text(urdf_text(UR6, "ur6"))
    sim = tmp_path / "sim"
    r = run_cli_here(
        "simulate", "--robot", urdf, "--out", sim, "--n-train", "40", "--n-test", "5"
    )
    assert r.returncode == 0, r.stderr
    cal = tmp_path / "cal"
    r = run_cli_here(
        "calibrate", sim / "train.csv", "--robot", sim / "robot.yaml",
        "--model", "full", "--cv", "off", "--out", cal,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    html = (cal / "report.html").read_text()
    # DH table, compliance table and the table of every parameter
    assert "<td class=l>J2 <small class=muted>shoulder_lift</small></td>" in html
    assert "joint2.d <small class=muted>shoulder_lift</small>" in html
    assert "joint3.lambda <small class=muted>elbow</small>" in html
    assert "link3.m <small class=muted>elbow</small>" in html
    # model.yaml keeps the canonical names
    assert "joint2.d:" in (cal / "model.yaml").read_text()


def test_default_joint_names_are_not_shown():
    assert name_cell({"name": "joint2.d"}) == "joint2.d"
    assert name_cell({"name": "joint2.d", "joint_name": "a<b"}) == (
        "joint2.d <small class=muted>a&lt;b</small>"
    )
    c = {"parameters": [{"name": "joint2.d", "joint_name": "lift"}, {"name": "base.x"}]}
    assert _shown(c, ["joint2.d", "base.x"]) == ["joint2.d (lift)", "base.x"]
