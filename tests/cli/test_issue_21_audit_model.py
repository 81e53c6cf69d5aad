"""Issue 21 audit (commands that read a model.yaml, program files and URDFs): an answer
with exit 0 on data that cannot give one, options silently ignored, an unclosed program
record, messages without the file. In-process, on one small kinematic calibration."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.cli_contract import check_contract, failed_with, run_kinecal

ROBOT = "fanuc-lrmate200id"


_bad = failed_with


@pytest.fixture(scope="module")
def cal(tmp_path_factory):
    """A kinematic calibration on 30 simulated tracker poses, and its data."""
    from kinecal.identification import calibrate
    from kinecal.io import save_model, write_measurements
    from kinecal.simulation import LaserTracker, experiment2

    d = tmp_path_factory.mktemp("audit-model")
    e = experiment2(5, tracker=LaserTracker(5e-6, 0.0), n_side=4, n_train=30)
    write_measurements(d / "train.csv", e.train, e.truth.robot)
    save_model(
        d / "model.yaml", calibrate(e.truth.robot, e.train, "kinematic").calibrated
    )
    return d


def test_issue_21_audit_refit_on_copies_of_one_pose(cal, capsys, tmp_path):
    """Was exit 0 with an RMS of 2e-13 mm: the refitted user frame absorbed it all."""
    lines = (cal / "train.csv").read_text().splitlines()
    f = tmp_path / "same.csv"
    f.write_text("\n".join([lines[0]] + [lines[1]] * 20) + "\n")
    res = run_kinecal(
        capsys, "evaluate", f, "--model", cal / "model.yaml", "--json",
        "--refit", "user,tool",
    )  # fmt: skip
    _bad(res, "same.csv", "only 1 distinct pose", "--refit user,tool", "at least 3")
    # without --refit the same rows are a valid (if poor) evaluation
    res = run_kinecal(capsys, "evaluate", f, "--model", cal / "model.yaml", "--json")
    check_contract(res)
    assert res.code == 0, str(res)


def test_issue_21_audit_empty_refit_is_refused(cal, capsys):
    res = run_kinecal(
        capsys,
        "evaluate",
        cal / "train.csv",
        "--model",
        cal / "model.yaml",
        "--refit",
        "",
    )
    _bad(res, "--refit", "got ''")


def test_issue_21_audit_fk_unknown_set_names_the_option(cal, capsys):
    res = run_kinecal(
        capsys, "fk", "--model", cal / "model.yaml", "--set", "zz", "--",
        "0", "0", "0", "0", "-30", "0",
    )  # fmt: skip
    _bad(
        res,
        "--set",
        "set 'zz' is not in the model",
        "only the default set (leave --set out)",
    )


def test_issue_21_audit_export_marker_and_set(cal, capsys, tmp_path):
    out = tmp_path / "c.urdf"
    m = cal / "model.yaml"
    res = run_kinecal(capsys, "export-urdf", m, "--out", out, "--marker", "zz")
    _bad(res, "--marker", "yaml-dh")  # was ignored with exit 0
    res = run_kinecal(
        capsys, "export-urdf", m, "--out", out, "--format", "yaml-dh", "--marker", "zz"
    )
    _bad(res, "--marker", "marker 'zz' is not in the model", "model.yaml")
    res = run_kinecal(capsys, "export-urdf", m, "--out", out, "--set", "zz")
    _bad(res, "--set", "set 'zz' is not in the model")
    assert not out.exists()


def test_issue_21_audit_unclosed_fanuc_position(cal, capsys, tmp_path):
    """An unclosed P[] record lent its name to the next one (exit 0)."""
    q = np.degrees(np.array([0.1, 0.2, -0.1, 0.0, -1.0, 0.5]))
    pos = ",\t".join(f"J{k + 1}= {v:10.3f} deg" for k, v in enumerate(q))
    prog = (
        "/PROG  AUDIT\n/MN\n   1:J P[1] 100% FINE    ;\n/POS\nP[99]{ garbage\n"
        f"P[1]{{\n   GP1:\n\tUF : 0, UT : 1,\n\t{pos}\n}};\n/END\n"
    )
    f = tmp_path / "audit.ls"
    f.write_text(prog)
    out = tmp_path / "c.ls"
    res = run_kinecal(
        capsys, "compensate", f, "--model", cal / "model.yaml", "--out", out, "-q"
    )
    _bad(res, "audit.ls", "line 5", "P[99] is not closed", "line 6")
    assert not out.exists()


def test_compensate_out_named_for_another_kind_is_refused(cal, capsys, tmp_path):
    """A FANUC program in, --out c.csv: the program was written under a CSV's name."""
    import shutil

    data = Path(__file__).resolve().parents[1] / "data" / "programs"
    prog = tmp_path / "pick.ls"
    shutil.copy(data / "pick_demo.ls", prog)
    m = cal / "model.yaml"
    for out, needles in (
        ("c.csv", ["--out", "c.csv", "fanuc-ls program", "as .ls"]),
        ("c.script", ["--out", "c.script", "fanuc-ls program", "as .ls"]),
    ):
        res = run_kinecal(
            capsys, "compensate", prog, "--model", m, "--out", tmp_path / out, "-q"
        )
        _bad(res, *needles, code=2)
        assert not (tmp_path / out).exists()
    res = run_kinecal(
        capsys, "compensate", prog, "--model", m, "--out", tmp_path / "c.ls", "-q"
    )
    assert res.code == 0, str(res)


def _urdf(tmp_path, joints: str):
    f = tmp_path / "r.urdf"
    f.write_text(
        '<?xml version="1.0"?><robot name="r"><link name="base"/><link name="l1"/>'
        f'<link name="l2"/>{joints}</robot>'
    )
    return f


_J1 = (
    '<joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>'
    '<axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>'
)


def test_issue_21_audit_urdf_with_one_joint_names_the_file(capsys, tmp_path):
    fixed = '<joint name="f" type="fixed"><parent link="l1"/><child link="l2"/></joint>'
    f = _urdf(tmp_path, _J1 + fixed)
    res = run_kinecal(capsys, "import-urdf", f, "--out", tmp_path / "r.yaml")
    _bad(res, "r.urdf", "one movable joint ('j1')", "at least 2")


def test_issue_21_audit_urdf_joint_without_name(capsys, tmp_path):
    j2 = (
        '<joint type="revolute"><parent link="l1"/><child link="l2"/>'
        '<origin xyz="0 0 0.3"/><axis xyz="0 1 0"/></joint>'
    )
    f = _urdf(tmp_path, _J1 + j2)
    res = run_kinecal(capsys, "import-urdf", f, "--out", tmp_path / "r.yaml")
    _bad(res, "r.urdf", "joint 2 (in file order) has no name")
