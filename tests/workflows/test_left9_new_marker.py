"""A new session with a marker the model has never seen (a re-mounted or new SMR):
``evaluate --refit marker`` (or ``tool``) fits its offset, as ``--refit user,tool`` fits
the frames of a new set-up, and scores the rest of the model.

Before, every data set with a marker label the model lacked was refused ("marker 'C' is
not in the model"), whatever ``--refit`` said; and a refit of the user frames of a new
set registered the rows of a model's second marker with its first marker's frame (an RMS
of 29 mm for data that score 0.014 mm)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from kinecal.errors import DataError, IdentifiabilityError
from kinecal.measurement import Measurements

# Offsets of the tracker's reflectors in the cam frame [m]: A and B calibrated, C new.
OFFSETS = {
    "A": np.zeros(3),
    "B": np.array([0.030, -0.020, 0.015]),
    "C": np.array([-0.025, 0.010, 0.040]),
}
NOISE = 5e-6  # per axis [m]


@pytest.fixture(scope="module")
def twin():
    """A kinematic model calibrated on markers A and B of the twin, and a function that
    measures 60 other poses with given markers (point or pose data)."""
    from kinecal.identification import calibrate
    from kinecal.simulation import LaserTracker, experiment2

    e = experiment2(3, tracker=LaserTracker(NOISE, 0.0), n_side=5, n_train=80)
    rng = np.random.default_rng(5)
    test = e.test.subset(np.sort(rng.choice(e.test.n, 60, replace=False)))

    def measure(base: Measurements, labels: tuple[str, ...], kind="point", sets=("",)):
        k = np.arange(base.n) % len(labels)
        p_cam = np.array([OFFSETS[lab] for lab in labels])[k]
        p, R = e.truth.evaluate(base.q_ctrl, p_cam=p_cam, orientation=kind == "pose")
        p = p + rng.normal(size=p.shape) * NOISE
        return replace(
            base,
            kind=kind,
            p=p,
            R_user_cam=R,
            marker_labels=labels,
            marker_index=k.astype(np.intp),
            set_labels=sets,
        )

    res = calibrate(e.truth.robot, measure(e.train, ("A", "B")), "kinematic")
    return res.calibrated, lambda *a, **k: measure(test, *a, **k), e.truth


def _score(cal, meas, refit=()):
    from kinecal.workflows import evaluate_measurements

    return evaluate_measurements(cal, meas, refit=refit).evaluation


def test_new_marker_offset_is_fitted_and_scores_near_the_noise_floor(twin):
    cal, measure, truth = twin
    known = _score(cal, measure(("A",)), ("marker",)).metrics.rms_mm
    ev = _score(cal, measure(("C",)), ("marker",))
    # the same poses as a known marker: the model's own error (noise floor 8.7 um)
    assert ev.metrics.n == 60
    assert ev.metrics.rms_mm < 1.25 * known and ev.metrics.rms_mm < 0.025
    # the fitted offset is C's: 40 mm off A's were it taken for A (or left at 0)
    _, t_cam = ev.calibrated.model.cam_frames(ev.calibrated.params)
    labels = ev.calibrated.model.spec.markers
    assert labels == ("A", "B", "C")
    R_flange_cam, _ = truth.model.cam_frames(truth.params)  # the truth's, one marker
    step = R_flange_cam[0] @ (OFFSETS["C"] - OFFSETS["A"])
    assert np.linalg.norm(t_cam[2] - t_cam[0] - step) < 5e-5
    # the tool refit (every cam frame) and a new set-up (user and marker) agree
    for refit, sets in ((("tool",), ("",)), (("user", "marker"), ("next",))):
        got = _score(cal, measure(("C",), sets=sets), refit).metrics.rms_mm
        assert got < 1.25 * known, refit


def test_known_and_new_marker_together(twin):
    cal, measure, _ = twin
    ev = _score(cal, measure(("A", "C")), ("marker",))
    assert ev.metrics.rms_mm < 0.025


def test_new_marker_of_pose_data_keeps_the_tool_orientation(twin):
    """Pose data: a new marker's frame starts from the first marker's (its rotation:
    points on one tool), and --refit marker fits its offset (its rotation was the
    identity: 180 deg orientation errors)."""
    _, measure, truth = twin
    from kinecal.identification import calibrate
    from kinecal.simulation import LaserTracker, experiment2

    e = experiment2(3, tracker=LaserTracker(NOISE, 0.0), n_side=4, n_train=60)
    p, R = truth.evaluate(e.train.q_ctrl, orientation=True)
    pose = replace(e.train, kind="pose", p=p, R_user_cam=R, marker_labels=("A",))
    cal_pose = calibrate(truth.robot, pose, "kinematic").calibrated
    ev = _score(cal_pose, measure(("C",), kind="pose"), ("marker",))
    assert ev.metrics.rot_rms_deg < 0.01 and ev.metrics.rms_mm < 0.025


def test_new_set_of_a_models_second_marker(twin):
    """--refit user on a new set of marker B's rows: registered with B's frame."""
    cal, measure, _ = twin
    ev = _score(cal, measure(("B",), sets=("next",)), ("user",))
    assert ev.metrics.rms_mm < 0.025


def test_new_marker_without_its_refit_names_the_refit(twin):
    cal, measure, _ = twin
    for refit in ((), ("user",)):
        with pytest.raises(DataError, match=r"marker 'C' is not in the model.*--refit"):
            _score(cal, measure(("C",)), refit)


def test_new_marker_of_too_few_poses_is_refused_with_its_count(twin):
    cal, measure, _ = twin
    meas = measure(("A", "C"))
    keep = np.flatnonzero((meas.marker_index == 0) | (np.arange(meas.n) < 4))
    few = meas.subset(keep)  # C in rows 1 and 3 only
    with pytest.raises(IdentifiabilityError, match=r"marker 'C'.* 2 distinct poses"):
        _score(cal, few, ("marker",))


def test_cli_new_marker_refit_and_its_refusal(twin, tmp_path, capsys):
    from kinecal.io import save_model, write_measurements
    from tests.cli_contract import failed_with, run_kinecal

    cal, measure, truth = twin
    save_model(tmp_path / "model.yaml", cal)
    meas = measure(("A", "C"))
    write_measurements(tmp_path / "new.csv", meas, truth.robot)
    few = meas.subset(np.flatnonzero((meas.marker_index == 0) | (np.arange(60) < 4)))
    write_measurements(tmp_path / "few.csv", few, truth.robot)
    model = tmp_path / "model.yaml"
    res = run_kinecal(capsys, "evaluate", tmp_path / "new.csv", "--model", model,
                      "--refit", "marker", "--json")  # fmt: skip
    assert res.code == 0, str(res)
    assert '"n": 60' in res.out
    res = run_kinecal(capsys, "evaluate", tmp_path / "few.csv", "--model", model,
                      "--refit", "tool")  # fmt: skip
    failed_with(res, "few.csv", "marker 'C'", "2 distinct poses", "at least 3")
    res = run_kinecal(capsys, "evaluate", tmp_path / "new.csv", "--model", model)
    failed_with(res, "marker 'C' is not in the model", "--refit marker")
