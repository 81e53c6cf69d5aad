"""The calibration workflow of ``kinecal calibrate``: the model chosen (``auto``: by
cross-validation over regions of the workspace) or given, the calibration, the checks
of the nominal robot and of gravity-like residuals, and the held-out figures of ``--cv``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from kinecal._stats import distinct_rows
from kinecal.errors import CalibError, IdentifiabilityError
from kinecal.identification import (
    CalibrationOptions,
    CalibrationResult,
    HeldOutAccuracy,
    Selection,
    calibrate,
    held_out_accuracy,
    nominal_check,
    select_model,
    spec_for,
)
from kinecal.measurement import Measurements
from kinecal.models import CalibrationModel, ModelSpec, parallel_pairs
from kinecal.robot import RobotDescription

__all__ = [
    "CalibrationRun",
    "calibrate_measurements",
    "check_auto_folds",
    "check_distinct_poses",
]

# The nominal check's extra fit runs up to this many rows (on large data the priors
# hardly matter).
NOMINAL_CHECK_ROWS = 20000

Progress = Callable[[str, str], None]


@dataclass(frozen=True)
class CalibrationRun:
    """What :func:`calibrate_measurements` found.

    Attributes
    ----------
    result : the calibration (model, metrics, diagnostics, uncertainty).
    spec : the model layout calibrated (``auto:<label>`` when chosen by ``auto``).
    options : the options it was calibrated with (the chosen prior strength included).
    selection : the table behind ``auto``'s choice (None for a given model).
    held_out : the in-session and new-region / new-session figures (None without
        ``cv_folds``).
    hayati, ntm_joints : the Hayati joints and the transmission joints used.
    """

    result: CalibrationResult
    spec: ModelSpec
    options: CalibrationOptions
    selection: Selection | None = field(default=None, repr=False)
    held_out: HeldOutAccuracy | None = None
    hayati: tuple[int, ...] = ()
    ntm_joints: tuple[int, ...] = ()

    def report_extra(self) -> dict[str, Any]:
        """report.json's sections beyond the calibration: ``model_selection`` and
        ``cross_validation`` when they ran."""
        out: dict[str, Any] = {}
        if self.selection is not None:
            out["model_selection"] = self.selection.as_dict()
        if self.held_out is not None:
            out["cross_validation"] = self.held_out.as_dict()
        return out


def calibrate_measurements(
    robot: RobotDescription,
    meas: Measurements,
    *,
    model: str = "auto",
    options: CalibrationOptions | None = None,
    hayati: bool = False,
    ntm_joints: tuple[int, ...] | None = None,
    ntm_order: int = 2,
    cv_folds: int | None = None,
    groups: np.ndarray | None = None,
    group_name: str = "group",
    jobs: int = 1,
    progress: Progress | None = None,
) -> CalibrationRun:
    """Calibrate ``robot`` on ``meas`` as ``kinecal calibrate`` does.

    ``model``: ``kinematic``, ``ntm``, ``rfcm``, ``full`` or ``auto`` (the default: the
    terms the data support, by cross-validation over regions of the workspace, or whole
    sets when there are several). ``cv_folds``: also the held-out figures of that many
    folds (the same folds as ``auto``'s). ``groups``: a label per row whose equal values
    stay in one fold.

    Raises
    ------
    IdentifiabilityError
        Too few (distinct) poses for the model, or for ``auto``'s folds.
    CalibError
        A fold of the cross-validation could not be fitted.
    """
    opts = options or CalibrationOptions()
    say: Progress = progress or (lambda stage, detail: None)
    hay = parallel_pairs(robot) if hayati else ()
    nj = tuple(ntm_joints or robot.ntm_joints)
    k = cv_folds or 5
    sel = None
    if model == "auto":
        smallest = spec_for(robot, meas, "kinematic")
        check_distinct_poses(meas, robot, smallest)
        check_auto_folds(meas, robot, smallest, k)
        say("auto", "cross-validating candidate models")
        sel = select_model(
            robot,
            meas,
            options=opts,
            hayati=hay,
            ntm_joints=nj,
            progress=say,
            jobs=jobs,
            groups=groups,
            group_name=group_name,
            k=k,
        )
        spec = sel.spec
        opts = replace(opts, prior_scale=sel.prior_scale)
        for w in sel.warnings:
            say("auto", w)
    else:
        spec = spec_for(
            robot, meas, model, hayati=hay, ntm_joints=nj, ntm_order=ntm_order
        )
    check_distinct_poses(meas, robot, spec)
    # auto: when the largest candidate won, its calibration on every row is the
    # selection's shared one (finished), not run again.
    result = (sel.calibration(opts) if sel is not None else None) or calibrate(
        robot, meas, spec, opts, progress=say
    )
    _checks(result, robot, meas, opts, say)
    held = None
    if cv_folds:
        say("cv", f"{cv_folds}-fold cross-validation: nominal and model, random poses "
            "and regions")  # fmt: skip
        try:
            held = held_out_accuracy(
                robot,
                meas,
                spec,
                cv_folds,
                options=opts,
                groups=groups,
                group_name=group_name,
                selection=sel,
                jobs=jobs,
                progress=say,
            )
        except CalibError as exc:
            raise type(exc)(
                f"--cv {cv_folds}: a fold's calibration failed: {exc}"
            ) from exc
    return CalibrationRun(result, spec, opts, sel, held, hay, nj)


def _checks(
    result: CalibrationResult,
    robot: RobotDescription,
    meas: Measurements,
    opts: CalibrationOptions,
    say: Progress,
) -> None:
    """The nominal robot and the priors against the data (one more fit without priors:
    a wrong nominal table or units), and gravity-like residuals on a robot without a
    self-weight layout; their findings join the result's diagnostics."""
    from kinecal.identification._gravity_check import gravity_check

    if opts.priors != "none" and meas.n <= NOMINAL_CHECK_ROWS:
        say("check", "the nominal robot and the priors against the data")
        result.diagnostics.extend(nominal_check(result, robot, meas, options=opts))
    found = gravity_check(result, meas)
    if found is not None:
        result.diagnostics.append(found)


def check_distinct_poses(
    meas: Measurements, robot: RobotDescription, spec: ModelSpec
) -> None:
    """Refuse data whose distinct poses cannot determine the model (100 copies of one
    pose are one pose): the same rule as for too few rows, on distinct rows."""
    cols = [meas.q_ctrl, meas.set_index[:, None], meas.marker_index[:, None]]
    if meas.target_index is not None:
        cols.append(meas.target_index[:, None])
    distinct = distinct_rows(np.hstack(cols))
    if distinct == meas.n:
        return
    size = CalibrationModel(robot, spec).size
    c = meas.components
    if distinct * c <= size:
        raise IdentifiabilityError(
            f"{meas.source}: the {meas.n} rows hold only {distinct} distinct pose"
            f"{'s' if distinct != 1 else ''} (joint angles, set, marker, target); the "
            f"'{spec.name}' model has {size} parameters: expected at least "
            f"{size // c + 1} different poses (several times more for a reliable result)"
        )


def check_auto_folds(
    meas: Measurements, robot: RobotDescription, spec: ModelSpec, k: int = 5
) -> None:
    """``--model auto``: refuse data whose cross-validation folds cannot fit even the
    smallest candidate ``spec`` (each fold is fitted on about (k-1)/k of the rows)."""
    size = CalibrationModel(robot, spec).size
    c = meas.components

    def train(n: int) -> int:
        return n - math.ceil(n / k)

    if train(meas.n) * c > size:
        return
    need = meas.n + 1
    while train(need) * c <= size:
        need += 1
    raise IdentifiabilityError(
        f"{meas.source}: --model auto cross-validates in {k} folds, each fitted on about "
        f"{train(meas.n)} of the {meas.n} poses ({train(meas.n) * c} residuals), but "
        f"the smallest candidate '{spec.name}' has {size} parameters; expected at least "
        f"{need} poses (several times more for a reliable choice), or a fixed --model."
    )
