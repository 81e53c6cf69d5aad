"""Issue 32, points 3a/3b: stages own their settings; a constant Problem beside a
workspace for its caches (shared by fits with other options on the same rows)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from kinecal.identification import CalibrationOptions, calibrate, default_stages
from kinecal.identification._diagnose import Diagnose
from kinecal.identification._options import (
    FitSettings,
    IdentifySettings,
    PriorSettings,
    RejectSettings,
)
from kinecal.identification._priors import EvidencePriors, Priors
from kinecal.identification._problem import Problem, Workspace, run_stages
from kinecal.identification._robust import RobustRejection
from kinecal.identification._stages import Identify, KinematicStage, TransmissionStage
from kinecal.models import pass_counts


def test_default_stages_carry_the_settings_of_the_options():
    opts = CalibrationOptions(
        loss="soft_l1", priors="compliance", reject="off", stage2="project"
    ).tuned(
        f_scale_mm=0.2, max_iter=40, drop_tol=1e-7, prior_scale=2.0,
        adapt_priors=False, outlier_p=1e-4,
    )  # fmt: skip
    stages = {type(s): s for s in default_stages(opts)}
    assert stages[KinematicStage].settings == FitSettings("soft_l1", 0.2, 40)
    assert stages[Identify].settings == IdentifySettings(1e-7, 1e-3)
    prior = PriorSettings("compliance", None, 2.0, False)
    assert stages[Priors].settings == prior == stages[EvidencePriors].settings
    assert stages[TransmissionStage].method == "project"
    reject = RejectSettings("off", None, 1e-4, "soft_l1")
    assert stages[RobustRejection].settings == reject == stages[Diagnose].settings
    assert stages[Diagnose].priors == prior
    # The rejection's probe: a robust kinematic fit (Huber for a linear loss).
    probe = stages[RobustRejection].probe[-1]
    assert isinstance(probe, KinematicStage) and probe.settings is not None
    linear = next(
        s
        for s in default_stages(CalibrationOptions())
        if isinstance(s, RobustRejection)
    )
    assert linear.probe[-1].settings == FitSettings("huber", None, 100)
    # Without options the stages read the problem's when they run.
    assert all(getattr(s, "settings", None) is None for s in default_stages()), (
        "settings without options"
    )


def test_a_stage_runs_with_its_own_settings_not_the_problems(exp2_exact):
    """Identify with a drop tolerance of its own holds what that tolerance says, on a
    problem whose options say otherwise."""
    e = exp2_exact
    problem = Problem.make(e.truth.robot, e.train, "full", CalibrationOptions())
    start = run_stages(problem, problem.start(), default_stages()[:1])
    own = Identify(settings=IdentifySettings(drop_tol=0.5, weak_tol=0.9))(
        problem, start
    )
    default = Identify()(problem, start)
    assert own.free.sum() < default.free.sum()
    loose = problem.with_options(CalibrationOptions().tuned(drop_tol=0.5, weak_tol=0.9))
    np.testing.assert_array_equal(Identify()(loose, start).free, own.free)


def test_the_problem_is_constant_and_its_caches_are_in_the_workspace(exp2_exact):
    e = exp2_exact
    problem = Problem.make(e.truth.robot, e.train, "full", CalibrationOptions())
    assert isinstance(problem.workspace, Workspace)
    tuned = problem.with_options(CalibrationOptions().tuned(max_iter=7))
    assert tuned.start().lm.max_iter == 7 and problem.start().lm.max_iter == 100
    with pytest.raises(dataclasses.FrozenInstanceError):
        problem.options = CalibrationOptions()  # type: ignore[misc]
    for a in (problem.groups, problem.kinematic, problem.frames):
        assert not a.flags.writeable
    # No mutable container among its fields: the caches live in the workspace.
    for f in dataclasses.fields(problem):
        assert not isinstance(getattr(problem, f.name), (dict, list, set)), f.name
    # Other options (the rejection's robust probe): the same rows, caches of its own.
    other = problem.with_options(CalibrationOptions(loss="huber"))
    assert other.options.loss == "huber" and other.meas is problem.meas
    assert other.workspace is not problem.workspace
    rows = np.ones(e.train.n, bool)
    rows[:7] = False
    state = problem.start(rows)
    view = problem.on(state)
    assert view.meas.n == e.train.n - 7 and view.root is problem
    assert view.workspace is not problem.workspace
    assert problem.on(state).workspace is view.workspace  # kept for those rows
    assert problem.on(problem.start()) is problem


def test_the_nominal_check_reuses_the_calibrations_workspace(exp2_exact):
    """The fit from the calibration's solution starts where the calibration ended: its
    Jacobian there is served from the calibration's workspace."""
    from kinecal.identification import nominal_check

    e = exp2_exact
    robot, meas = e.truth.robot, e.train
    res = calibrate(robot, meas, "full")
    assert res.workspace is not None and res.workspace.meas is meas
    # It keeps the evaluations at the solution alone.
    assert (
        res.workspace.evaluations.kept(res.model, res.params, res.weights) is not None
    )
    before = pass_counts()["jacobian"]
    found = nominal_check(res, robot, meas)
    with_ws = pass_counts()["jacobian"] - before
    bare = dataclasses.replace(res, workspace=None)
    before = pass_counts()["jacobian"]
    again = nominal_check(bare, robot, meas)
    without = pass_counts()["jacobian"] - before
    assert [d.message for d in found] == [d.message for d in again]
    assert with_ws < without


def test_the_options_are_what_the_command_line_maps_and_the_rest_is_tuning():
    """Issue 32 point 3: CalibrationOptions holds the options ``kinecal calibrate``
    maps (one option each), the stages' other settings are its Tuning."""
    import click

    from kinecal.cli import cli
    from kinecal.identification import Tuning

    top = [f.name for f in dataclasses.fields(CalibrationOptions)]
    assert top[-1] == "tuning"
    command = cli.get_command(click.Context(cli), "calibrate")
    assert command is not None
    names = {p.name for p in command.params}
    assert set(top[:-1]) <= names, set(top[:-1]) - names
    # Every setting a stage reads comes from the options or their tuning.
    tuning = {f.name for f in dataclasses.fields(Tuning)}
    for cls in (FitSettings, IdentifySettings, PriorSettings, RejectSettings):
        own = {f.name for f in dataclasses.fields(cls)}
        assert own <= tuning | set(top), (cls.__name__, own - tuning - set(top))
    opts = CalibrationOptions(loss="huber").tuned(max_iter=7, prior_scale=0.5)
    assert opts.loss == "huber" and opts.tuning.max_iter == 7
    assert FitSettings.of(opts) == FitSettings("huber", None, 7)
    assert PriorSettings.of(opts).prior_scale == 0.5


@pytest.mark.parametrize(
    "bad",
    [{"max_iter": 0}, {"drop_tol": 2.0}, {"outlier_p": 0.0}, {"prior_scale": -1.0},
     {"f_scale_mm": 0.0}],
)  # fmt: skip
def test_tuning_refuses_values_that_cannot_be_right(bad):
    with pytest.raises(ValueError, match=next(iter(bad))):
        CalibrationOptions().tuned(**bad)
    with pytest.raises(TypeError):
        CalibrationOptions().tuned(no_such_setting=1)
    with pytest.raises(TypeError, match="Tuning"):
        CalibrationOptions(tuning={"max_iter": 3})  # type: ignore[arg-type]
