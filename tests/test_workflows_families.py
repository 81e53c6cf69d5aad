"""kinecal.workflows (issue 32 point 1): each command family's workflow, called in a
few lines, gives what the command (run in this process) prints and writes."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from kinecal.io import load_model, read_measurements
from kinecal.robot import load_robot
from kinecal.workflows import (
    compare_measurements,
    compensate_program,
    compensate_targets,
    evaluate_measurements,
    export_model,
    fit_cloud_sphere,
    forward_pose,
    import_urdf_robot,
    plan_candidates,
    plan_measurements,
    plan_setup,
    reconstruct_scan,
    render_scan,
    simulate_robot_twin,
)
from tests.cli_contract import make_point_data, run_kinecal

DATA = Path(__file__).parent / "data"


@pytest.fixture(scope="module")
def point(tmp_path_factory):
    return make_point_data(tmp_path_factory.mktemp("workflows"))


def _ok(capsys, *args):
    res = run_kinecal(capsys, *map(str, args))
    assert res.code == 0, str(res)
    return res


def test_export_and_fk_workflows_are_the_commands(point, tmp_path, capsys):
    cal = load_model(point["model"])
    for fmt in ("urdf", "yaml-dh"):
        out = tmp_path / f"x.{fmt}"
        _ok(capsys, "export-urdf", point["model"], "--out", out, "--format", fmt)
        ex = export_model(cal, fmt, model_name=str(point["model"]))
        assert out.read_text() == ex.text
    joints = ["30", "20", "-10", "45", "-60", "90"]
    res = _ok(capsys, "fk", "--model", point["model"], "--json", "--", *joints)
    pose = forward_pose(cal, [float(j) for j in joints])
    assert json.loads(res.out) == pose.as_dict()
    res = _ok(capsys, "fk", "--robot", "fanuc-lrmate200id", "--json", "--", *joints)
    nominal = forward_pose(load_robot("fanuc-lrmate200id"), [float(j) for j in joints])
    assert json.loads(res.out) == nominal.as_dict() and nominal.kinematic is None


def test_import_urdf_workflow_is_the_command(tmp_path, capsys):
    urdf = DATA / "fanuc_lrmate200id" / "fanuc_lrmate200id.urdf"
    out = tmp_path / "robot.yaml"
    res = _ok(capsys, "import-urdf", urdf, "--out", out)
    imp = import_urdf_robot(str(urdf))
    assert out.read_text() == imp.text
    assert res.out.splitlines()[1] == imp.self_weight


def test_evaluate_and_compare_workflows_are_the_commands(point, capsys):
    cal = load_model(point["model"])
    robot = cal.model.robot
    test = read_measurements(point["test"], robot, check=False)
    res = _ok(capsys, "evaluate", point["test"], "--model", point["model"], "--json")
    ev = evaluate_measurements(cal, test, data_name=str(point["test"]))
    assert json.loads(res.out) == json.loads(
        json.dumps(ev.evaluation.metrics.contract())
    )
    train = read_measurements(point["train"], robot, check=False)
    res = _ok(capsys, "compare", point["train"], point["test"], "--robot",
              "fanuc-lrmate200id", "--models", "kinematic", "--json", "-q")  # fmt: skip
    cmp = compare_measurements(robot, train, test, ("kinematic",))
    got = [{k: v for k, v in r.items() if k != "seconds"} for r in json.loads(res.out)]
    want = [{k: v for k, v in r.items() if k != "seconds"} for r in cmp.table]
    assert got == json.loads(json.dumps(want))
    with pytest.raises(ValueError, match="expected some of"):
        compare_measurements(robot, train, test, ("exact",))


def test_compensate_workflows_are_the_command(point, tmp_path, capsys):
    from kinecal.io import program_bytes

    cal = load_model(point["model"])
    out = tmp_path / "c.csv"
    res = _ok(capsys, "compensate", point["targets"], "--model", point["model"],
              "--out", out, "--json")  # fmt: skip
    tc = compensate_targets(cal, point["targets"])
    assert out.read_text() == tc.csv_text()
    assert json.loads(res.out) == {**tc.summary(), "out": str(out)}
    prog = DATA / "programs" / "pick_demo.ls"
    out, rep = tmp_path / "c.ls", tmp_path / "c.report.csv"
    res = _ok(capsys, "compensate", prog, "--model", point["model"], "--out", out,
              "--report", rep, "--allow-unreachable")  # fmt: skip
    pc = compensate_program(cal, prog, "fanuc-ls")
    assert out.read_bytes() == program_bytes(pc.text) and rep.read_text() == pc.report
    assert all(m in res.err for m in pc.messages)


def test_plan_workflow_is_the_command(tmp_path, capsys):
    out = tmp_path / "plan.csv"
    _ok(capsys, "plan", "--robot", "fanuc-lrmate200id", "--model", "kinematic",
        "--poses", "12", "--n-candidates", "200", "--random-draws", "2", "--out", out,
        "-q")  # fmt: skip
    setup = plan_setup(load_robot("fanuc-lrmate200id"), "kinematic")
    cand = plan_candidates(setup, n=200)
    run = plan_measurements(setup, cand, 12, random_draws=2)
    assert out.read_text() == run.csv_text()
    rep = json.loads((tmp_path / "plan.report.json").read_text())
    assert rep["order"] == run.report["order"]
    assert rep["predicted"] == run.report["predicted"]


def test_simulate_workflow_is_the_command(tmp_path, capsys):
    out = tmp_path / "sim"
    _ok(capsys, "simulate", "--robot", "ur10", "--n-train", "20", "--n-test", "10",
        "--out", out, "-q")  # fmt: skip
    sim = simulate_robot_twin(load_robot("ur10"), n_train=20, n_test=10)
    meas = read_measurements(out / "train.csv", load_robot("ur10"))
    np.testing.assert_allclose(meas.q_ctrl, sim.experiment.train.q_ctrl, atol=1e-9)
    np.testing.assert_allclose(meas.p, sim.experiment.train.p, atol=1e-9)


def test_sensor_workflows_are_the_commands(tmp_path, capsys):
    from kinecal.sensor import paper_sensor

    scan = tmp_path / "scan"
    _ok(capsys, "sensor", "simulate-scan", "--out", scan, "--every", "24",
        "--center-mm", "0,0,125", "-q")  # fmt: skip
    own = tmp_path / "own"
    own.mkdir()
    ses = render_scan(own, (0.0, 0.0, 125.0), 15.001, every=24)
    for name in ses.files:
        assert (own / name).read_bytes() == (scan / name).read_bytes(), name
    cloud_csv = tmp_path / "cloud.csv"
    _ok(capsys, "sensor", "reconstruct", scan, "--sensor", scan / "sensor.yaml",
        "--out", cloud_csv, "-q")  # fmt: skip
    cloud = reconstruct_scan(own, paper_sensor())
    got = np.loadtxt(cloud_csv, delimiter=",", skiprows=1, usecols=(0, 1, 2))
    np.testing.assert_allclose(got, cloud.points * 1e3, atol=1e-5)
    res = _ok(capsys, "sensor", "fit-sphere", cloud_csv, "--json")
    from kinecal.workflows._sensor import sphere_dict

    want = sphere_dict(fit_cloud_sphere(cloud_csv))
    assert json.loads(res.out) == json.loads(json.dumps(want))


@pytest.mark.slow  # 1.4-4.3 s: in test-slow, to keep make test within its budget
def test_iso9283_program_workflow_is_the_command(tmp_path, capsys):
    from kinecal.workflows import iso_test_program

    out = tmp_path / "iso.csv"
    res = _ok(capsys, "plan", "--iso9283", "--robot", "fanuc-lrmate200id", "--cycles",
              "3", "--out", out)  # fmt: skip
    prog = iso_test_program(load_robot("fanuc-lrmate200id"), cycles=3)
    assert out.read_text() == prog.csv_text()
    assert res.out.splitlines()[:-1] == prog.summary_lines()
