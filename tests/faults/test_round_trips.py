"""Issue 35 (7): what any command writes, every command taking that kind of file reads
(a property of the command set, checked over every writer x reader pair below).

Writers: simulate's (tracker and sensor experiments, small: train/test CSVs, targets,
truth.yaml),
calibrate (model.yaml of point and sensor data), compare (model-*.yaml), export-urdf
--format yaml-dh (robot YAML), plan (PLAN.csv). Readers: every command taking a model,
a measurement file, a robot YAML or a joint list. (kinecal's exported URDF as --robot is
issue 35 point 6, tested with the URDF import.)
"""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.cli_contract import check_contract, run_kinecal

ROBOT = "fanuc-lrmate200id"


def _ok(capsys, *args):
    res = run_kinecal(capsys, *[str(a) for a in args])
    check_contract(res)
    assert res.code == 0, res
    return res


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    """Every writer run once, small; {name: path}."""

    from kinecal.simulation import experiment1, experiment2
    from kinecal.workflows import SimulatedData
    from kinecal.workflows._simulate import write_simulation

    capsys = _Capture()
    root = tmp_path_factory.mktemp("round-trips")
    e2, e1 = root / "exp2", root / "exp1"
    # simulate's own writer, on small experiments (the command plans 1000 poses)
    for d, exp in ((e2, experiment2(0, n_train=40, n_side=5)),
                   (e1, experiment1(0, n_train=30, per_sphere=10))):  # fmt: skip
        d.mkdir()
        write_simulation(SimulatedData(exp), d, d)
    _ok(
        capsys, "calibrate", "--cv", "off", e2 / "train.csv", "--robot", ROBOT, "--model",
        "kinematic", "--out", root / "cal2", "-q",
    )  # fmt: skip
    _ok(
        capsys, "calibrate", "--cv", "off", e1 / "train.csv", "--robot", ROBOT, "--model",
        "kinematic", "--targets", e1 / "targets.csv", "--out", root / "cal1", "-q",
    )  # fmt: skip
    _ok(
        capsys, "compare", e2 / "train.csv", e2 / "test.csv", "--robot", ROBOT,
        "--models", "kinematic,ntm", "--out", root / "cmp", "-q",
    )  # fmt: skip
    _ok(
        capsys, "export-urdf", root / "cal2" / "model.yaml", "--format", "yaml-dh",
        "--out", root / "robot-dh.yaml",
    )  # fmt: skip
    _ok(
        capsys, "plan", "--robot", ROBOT, "--model", "kinematic", "--poses", "30",
        "--n-candidates", "300", "--out", root / "plan.csv", "-q",
    )  # fmt: skip
    return {
        "exp2": e2,
        "exp1": e1,
        "point-model": root / "cal2" / "model.yaml",
        "sensor-model": root / "cal1" / "model.yaml",
        "truth-point": e2 / "truth.yaml",
        "truth-sensor": e1 / "truth.yaml",
        "compare-model": root / "cmp" / "model-ntm.yaml",
        "robot-dh": root / "robot-dh.yaml",
        "plan": root / "plan.csv",
    }


class _Capture:
    """capsys for the module fixture (output is not checked there)."""

    def readouterr(self):
        class _Out:
            out = err = ""

        return _Out()


MODELS = ["point-model", "sensor-model", "truth-point", "truth-sensor", "compare-model"]


def _data_for(w: dict[str, Path], model: str) -> list[object]:
    """The test data of the model's kind (with targets for sensor data)."""
    if "sensor" in model:
        return [w["exp1"] / "test.csv", "--targets", w["exp1"] / "targets.csv"]
    return [w["exp2"] / "test.csv"]


@pytest.mark.parametrize("model", MODELS)
def test_round_trip_model_evaluate(written, capsys, model):
    res = _ok(capsys, "evaluate", *_data_for(written, model), "--model", written[model])
    assert "RMS" in res.out


@pytest.mark.parametrize("model", MODELS)
def test_round_trip_model_fk(written, capsys, model):
    res = _ok(capsys, "fk", "--model", written[model], "0", "0", "0", "0", "90", "0")
    assert "mm" in res.out


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("fmt", ["urdf", "yaml-dh"])
def test_round_trip_model_export(written, capsys, tmp_path, model, fmt):
    _ok(
        capsys, "export-urdf", written[model], "--format", fmt, "--out",
        tmp_path / "out", *(["--data", *_data_for(written, model)]),
    )  # fmt: skip
    assert (tmp_path / "out").stat().st_size > 0


@pytest.mark.parametrize("model", ["point-model", "truth-point", "compare-model"])
def test_round_trip_model_compensate(written, capsys, tmp_path, model):
    _ok(
        capsys, "compensate", written["exp2"] / "targets.csv"
        if (written["exp2"] / "targets.csv").exists()
        else _targets(written, tmp_path), "--model", written[model],
        "--out", tmp_path / "comp.csv", "-q",
    )  # fmt: skip


def _targets(w: dict[str, Path], d: Path) -> Path:
    """Compensation targets from the tracker test set: the measured points with their
    joints as seeds."""
    import csv

    rows = list(csv.DictReader((w["exp2"] / "test.csv").open()))[:5]
    joints = [k for k in rows[0] if k.startswith("j")]
    f = d / "targets.csv"
    with f.open("w", newline="") as fh:
        out = csv.writer(fh)
        out.writerow(["x_mm", "y_mm", "z_mm", *joints])
        for r in rows:
            out.writerow([r["x_mm"], r["y_mm"], r["z_mm"], *(r[j] for j in joints)])
    return f


@pytest.mark.parametrize(
    "model",
    [
        m if "sensor" not in m else pytest.param(m, marks=pytest.mark.slow)
        for m in MODELS
    ],
)
def test_round_trip_model_plan_add(written, capsys, tmp_path, model):
    extra = ["--targets", written["exp1"] / "targets.csv"] if "sensor" in model else []
    _ok(
        capsys, "plan", "--model", written[model], "--add", "3", "--n-candidates",
        "100", *extra, "--out", tmp_path / "p.csv", "-q",
    )  # fmt: skip


@pytest.mark.parametrize(
    "robot", ["robot-dh", ROBOT]
)  # a robot YAML kinecal wrote, and a built-in
def test_round_trip_robot_yaml(written, capsys, tmp_path, robot):
    r = written.get(robot, robot)
    _ok(capsys, "fk", "--robot", r, "0", "0", "0", "0", "90", "0")
    _ok(
        capsys, "calibrate", "--cv", "off", written["exp2"] / "train.csv", "--robot", r, "--model",
        "kinematic", "--out", tmp_path / "cal", "-q",
    )  # fmt: skip
    _ok(
        capsys, "plan", "--robot", r, "--model", "kinematic", "--poses", "20",
        "--n-candidates", "100", "--out", tmp_path / "p.csv", "-q",
    )  # fmt: skip


def test_round_trip_plan_as_candidates(written, capsys, tmp_path):
    _ok(
        capsys, "plan", "--robot", ROBOT, "--candidates", written["plan"], "--model",
        "kinematic", "--poses", "20", "--out", tmp_path / "p.csv", "-q",
    )  # fmt: skip


def test_round_trip_simulated_data(written, capsys, tmp_path):
    _ok(
        capsys, "evaluate", written["exp2"] / "train.csv", "--model",
        written["point-model"],
    )  # fmt: skip
    _ok(
        capsys, "compare", written["exp1"] / "train.csv", written["exp1"] / "test.csv",
        "--robot", ROBOT, "--targets", written["exp1"] / "targets.csv", "--models",
        "kinematic", "--out", tmp_path / "cmp", "-q",
    )  # fmt: skip
    _ok(capsys, "report", written["point-model"].parent, "--out", tmp_path / "r.html")
