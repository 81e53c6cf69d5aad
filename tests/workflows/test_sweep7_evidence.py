"""The evidence scaling of the priors on a 3D-sensor calibration of the Kinova Gen3
(its URDF's masses, 3 kg payload): it shrank the compliance priors a hundredfold while
the link terms, which act only through the compliances, stood in for them in the
linearised evidence; the refit then left the compliances at zero and the held-out
error at 1.73x the truth's own. The compliances now take the link terms along when
they shrink: 1.15x."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

URDF = Path(__file__).resolve().parents[1] / "data/vendor_urdf/kinova_gen3_7dof.urdf"


def _rms(run, data, model, targets):
    r = run("evaluate", str(data), "--model", str(model), "--targets", str(targets),
            "--json", "-q")  # fmt: skip
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout)["rms_mm"]


@pytest.mark.filterwarnings("ignore")
def test_sensor_twin_reaches_the_truths_accuracy(tmp_path, run_cli_here):
    s = tmp_path / "s"
    r = run_cli_here(
        "simulate", "--robot", str(URDF), "--sensor", "--seed", "2", "--payload-kg",
        "3", "--n-train", "120", "--n-test", "50", "-q", "--out", str(s),
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    r = run_cli_here(
        "calibrate", str(s / "train.csv"), "--robot", str(s / "robot.yaml"),
        "--targets", str(s / "targets.csv"), "--model", "full", "--cv", "off",
        "--no-report", "-q", "--out", str(tmp_path / "c"),
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    rep = json.loads((tmp_path / "c/report.json").read_text())
    assert rep["prior_scale_by_evidence"]["load"] >= 0.1
    got = _rms(
        run_cli_here, s / "test.csv", tmp_path / "c/model.yaml", s / "targets.csv"
    )
    truth = _rms(run_cli_here, s / "test.csv", s / "truth.yaml", s / "targets.csv")
    assert got < 1.3 * truth, (got, truth)
