"""Issue 19: identification as a pipeline of stages, one registration path, structured
diagnostics."""

from __future__ import annotations

import inspect
from dataclasses import dataclass, replace

import numpy as np
import pytest

from kinecal.geometry import euler_zyx_to_matrix, matrix_to_euler_zyx
from kinecal.identification import (
    CODES,
    Diagnostic,
    EvidencePriors,
    FullStage,
    Measurements,
    Problem,
    State,
    calibrate,
    default_stages,
    evaluate,
    refit,
    refit_diagnosed,
)
from kinecal.identification import _calibrate as calibrate_module


def _robot():
    from kinecal.robot import load_robot

    return load_robot("fanuc-lrmate200id")


def _moved(meas: Measurements, R, t_m) -> Measurements:
    """The same poses seen from a tracker at another place (a new session)."""
    return replace(meas, p=meas.p @ R.T + np.asarray(t_m))


def test_issue_19_calibrate_is_a_short_recipe_of_stages():
    src = inspect.getsource(calibrate_module.calibrate)
    body = src[src.index('"""', src.index('"""') + 3) + 3 :]  # after the docstring
    assert len(body.strip().splitlines()) <= 10
    assert len(src.splitlines()) < 80
    names = [s.name for s in default_stages()]
    assert names[:2] == ["registration", "identifiability"]
    assert "stage 1: kinematic" in names and "stage 2: transmission" in names
    assert "stage 3: all" in names and "robust rejection" in names


def test_issue_19_a_user_runs_their_own_list_of_stages(exp2_exact):
    """Without the paper's stage 3 the full model keeps its compliance terms at zero; an
    extra stage of the user's sees the state and may change it."""
    e = exp2_exact
    robot = e.truth.robot

    @dataclass(frozen=True)
    class Count:
        seen: list
        name: str = "count"

        def __call__(self, problem: Problem, state: State) -> State:
            self.seen.append(int(state.free.sum()))
            return state

    seen: list[int] = []
    stages = [
        s for s in default_stages() if not isinstance(s, (FullStage, EvidencePriors))
    ]
    stages.insert(2, Count(seen))
    res = calibrate(robot, e.train, "full", stages=stages)
    assert len(seen) == 1 and seen[0] == res.identifiability.rank
    lam = res.model.layout.group_indices("load")
    assert np.all(res.params[lam] == 0.0)
    assert not any(s.name.startswith("stage 3") for s in res.stages)
    full = calibrate(robot, e.train, "full")
    assert np.any(full.params[lam] != 0.0)


def test_issue_19_diagnostics_are_structured(exp1_exact):
    e = exp1_exact
    two = e.train.subset(np.flatnonzero(e.train.target_index < 2))
    res = calibrate(_robot(), two, "kinematic")
    assert res.diagnostics and all(isinstance(d, Diagnostic) for d in res.diagnostics)
    assert all(d.code in CODES for d in res.diagnostics)
    (few,) = res.diagnostics_with("targets_few")
    assert few.parameters == ("base.r", "base.w", "base.p")
    assert few.as_dict()["code"] == "targets_few"
    assert res.warnings == [
        d.message for d in res.diagnostics if d.severity == "warning"
    ]
    with pytest.raises(ValueError, match="unknown diagnostic code"):
        Diagnostic("typo", "x")


def test_issue_19_frames_not_determined_fires_for_labelled_markers(exp2_exact):
    """One tool orientation cannot separate the tool point from the user origin. With a
    labelled marker (parameters ``cam@n.x``) the warning never fired: names were parsed."""
    e = exp2_exact
    label = e.plan.label[e.test.rows - 1]
    block = e.test.subset(np.flatnonzero(label == 0)[:300])
    block = replace(block, marker_labels=("n",))
    res = calibrate(_robot(), block, "kinematic")
    (lost,) = res.diagnostics_with("frames_undetermined")
    assert lost.parameters and all(
        n.startswith(("cam@n.", "base.")) for n in lost.parameters
    )
    assert any(n.startswith("cam@n.") for n in lost.parameters)


def test_issue_19_refit_keeps_a_gimbal_lock_margin(exp2_exact):
    """A new session whose user frame has a pitch of 89.5 deg: the refit (the same path
    as calibration) puts a reference rotation under it instead of working at gimbal lock,
    and scores the session as well as the calibration data."""
    e = exp2_exact
    robot = e.truth.robot
    res = calibrate(robot, e.train, "kinematic")
    R_old = res.model.base_frames(res.params)[0][0]
    R_new = euler_zyx_to_matrix(np.radians([30.0, 89.5, 10.0]))
    new = _moved(e.test.subset(np.arange(0, 600)), R_new @ R_old.T, [1.0, -2.0, 0.5])
    cal = refit(res.calibrated, new, ("base",))
    R_ref = cal.model.R_ref_base[0]
    assert not np.allclose(R_ref, np.eye(3))
    pitch = np.degrees(cal.params[cal.model.base_index[0, 4]])
    assert abs(abs(pitch) - 90.0) > 15.0
    R_total = cal.model.base_frames(cal.params)[0][0]
    assert np.degrees(matrix_to_euler_zyx(R_total))[1] == pytest.approx(89.5, abs=0.01)
    here = e.test.subset(np.arange(0, 600))
    same = evaluate(res.calibrated, here, refit_user=True).metrics.rms_mm
    assert evaluate(cal, new).metrics.rms_mm == pytest.approx(same, rel=1e-3)


def test_issue_19_refit_of_a_set_that_sees_two_targets(exp1_exact):
    """Sensor data of a new session that see two spheres: the user frame's rotation about
    the line through them is not determined. The refit gave a bare ValueError; now it
    returns the best registration and says what is undetermined."""
    e = exp1_exact
    res = calibrate(_robot(), e.train, "kinematic")
    two = e.test.subset(np.flatnonzero(e.test.target_index < 2))
    _, found = refit_diagnosed(res.calibrated, two, ("base",))
    (d,) = found
    assert d.code == "rotation_undetermined" and d.severity == "warning"
    assert d.parameters == ("base.r", "base.w", "base.p")
    ev = evaluate(res.calibrated, two, refit_user=True)
    assert [x.code for x in ev.diagnostics] == ["rotation_undetermined"]
    assert ev.metrics.rms_mm < 2.0 * evaluate(res.calibrated, two).metrics.rms_mm + 0.05
    with pytest.warns(UserWarning, match="not determined"):
        refit(res.calibrated, two)


def test_issue_19_refit_by_names_moves_only_those(exp2_exact):
    """``names=`` re-fits exactly those parameters: the user frame stays as it was."""
    e = exp2_exact
    res = calibrate(e.truth.robot, e.train, "kinematic")
    cal = refit(res.calibrated, e.test.subset(np.arange(300)), names=["joint2.a"])
    moved = np.flatnonzero(cal.params != res.calibrated.params)
    assert [cal.model.layout.names[i] for i in moved] == ["joint2.a"]
    with pytest.raises(ValueError, match=r"unknown parameter 'joint9\.a'"):
        refit(res.calibrated, e.test, names=["joint9.a"])
