"""The calibration workflow of ``kinecal calibrate``: the model chosen (``auto``: by
cross-validation over regions of the workspace) or given, the calibration, the checks
of the nominal robot and of gravity-like residuals, and the held-out figures of ``--cv``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from kinecal._record import Record
from kinecal._stats import distinct_rows
from kinecal.errors import CalibError, ConfigError, DataError, IdentifiabilityError
from kinecal.identification import (
    CalibrationOptions,
    CalibrationResult,
    calibrate,
    nominal_check,
    spec_for,
)
from kinecal.io._manifest import manifest
from kinecal.measurement import Diagnostic, Measurements
from kinecal.models import CalibrationModel, ModelSpec, parallel_pairs
from kinecal.robot import RobotDescription

if TYPE_CHECKING:
    from kinecal.identification import HeldOutAccuracy, Selection
    from kinecal.report import PoseErrors

__all__ = [
    "CalibrationFiles",
    "CalibrationRun",
    "calibrate_measurements",
    "calibration_files",
    "check_auto_folds",
    "check_cv_folds",
    "check_distinct_poses",
    "group_labels",
    "write_calibration",
]

# The nominal check's extra fit runs up to this many rows (on large data the priors
# hardly matter).
NOMINAL_CHECK_ROWS = 20000

Progress = Callable[[str, str], None]


@dataclass(frozen=True, eq=False, repr=False)
class CalibrationRun(Record):
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
    DataError
        A fit whose parameters no model file holds (another robot's data).
    CalibError
        A fold of the cross-validation could not be fitted.
    ConfigError
        Arguments of the wrong type or shape.
    """
    _check_arguments(robot, meas, options, cv_folds, groups, group_name)
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
        from kinecal.identification import select_model  # (cv: only when it runs)

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
        opts = opts.tuned(prior_scale=sel.prior_scale)
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
        from kinecal.identification import held_out_accuracy

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


@dataclass(frozen=True, eq=False, repr=False)
class CalibrationFiles(Record):
    """What ``kinecal calibrate`` writes of a :class:`CalibrationRun`.

    Attributes
    ----------
    summary : report.json's content: the calibration with its data checks, certificate,
        model selection, cross-validation, acceptance and accuracy blocks.
    errors : the per-pose errors on the calibration data (residuals.csv's rows).
    """

    summary: dict[str, Any] = field(repr=False)
    errors: PoseErrors = field(repr=False)

    def residuals_csv(self) -> Iterator[bytes]:
        """residuals.csv in blocks of rows (a large file's text is never held whole)."""
        return (b.encode("utf-8") for b in self.errors.csv_blocks())


def calibration_files(
    run: CalibrationRun,
    meas: Measurements,
    *,
    data_checks: Sequence[Diagnostic] = (),
    certificate: dict[str, Any] | None = None,
    limits: tuple[float, float | None] | None = None,
) -> CalibrationFiles:
    """report.json and residuals.csv of ``run`` on its data ``meas``, with the findings
    of the data's checks, the ``certificate`` block and the ``--accept`` verdict on the
    ``limits`` (RMS, max [mm]) when given."""
    from kinecal.report import calibration_summary, pose_errors
    from kinecal.report._acceptance import acceptance
    from kinecal.report._headline import accuracy_block

    result, held = run.result, run.held_out
    extra: dict[str, Any] = {"data_checks": [d.as_dict() for d in data_checks]}
    extra["certificate"] = certificate
    extra.update(run.report_extra())
    if limits is not None:
        extra["acceptance"] = acceptance(*limits, held, result.metrics_after)
    errors = pose_errors(result, meas)
    extra["accuracy"] = accuracy_block(errors, held)
    return CalibrationFiles(calibration_summary(result, extra=extra), errors)


def write_calibration(
    out: Path,
    run: CalibrationRun,
    files: CalibrationFiles,
    inputs: dict[str, str | None],
    settings: dict[str, Any],
    meta: dict[str, str],
    report: bool = True,
    progress: Progress | None = None,
) -> list[str]:
    """``kinecal calibrate``'s files into the folder ``out``: model.yaml, report.json,
    residuals.csv, manifest.json (the ``inputs`` files' hashes, the ``settings`` with
    the model code, the outputs' hashes and the certificate fields ``meta``) and
    report.html when ``report``; the names written."""
    from kinecal.io import atomic_write_bytes, write_json
    from kinecal.io._model_file import save_model_as_read
    from kinecal.models import kernel_name
    from kinecal.report import RESIDUALS_CSV

    say: Progress = progress or (lambda stage, detail: None)
    say("write", "model.yaml, report.json, residuals.csv, manifest.json")
    cal = run.result.calibrated
    _, model = save_model_as_read(out / "model.yaml", cal, force=True, read=report)
    write_json(out / "report.json", files.summary, force=True)
    atomic_write_bytes(out / RESIDUALS_CSV, files.residuals_csv(), force=True)
    written = ["model.yaml", "report.json", RESIDUALS_CSV, "manifest.json"]
    written += ["report.html"] if report else []
    settings = {**settings, "model_code": kernel_name(run.result.calibrated.model)}
    run_manifest = manifest(inputs, settings, files=written, folder=out)
    run_manifest["meta"] = meta
    write_json(out / "manifest.json", run_manifest, force=True)
    if report:  # drawn from the files just written, as `kinecal report DIR` does
        from kinecal.report import write_report

        say("report", "drawing report.html")
        write_report(out, force=True, poses=files.errors, model=model)
    return written


def group_labels(data: str, column: str, rows: np.ndarray) -> np.ndarray:
    """The values of ``column`` of the measurement file ``data``, one per row of the
    data (``rows``: their lines), for ``--cv-groups``."""
    from kinecal.errors import DataError
    from kinecal.io import read_table

    table = read_table(data)
    if column not in table.header:
        raise DataError(
            f"{data}: --cv-groups names column {column!r}, which the file does not "
            f"have (columns: {', '.join(table.header)})."
        )
    k = table.header.index(column)
    by_line = {line: row[k].strip() for line, row in zip(table.lines, table.rows)}
    labels = np.array([by_line[int(r)] for r in rows])
    empty = np.flatnonzero(labels == "")
    if empty.size:  # they made one group of their own, unsaid
        raise DataError(
            f"{data}: line {int(rows[empty[0]])}, column {column!r}: empty ({empty.size} "
            f"of {labels.size} rows); expected a group label in every row (--cv-groups)."
        )
    return labels


def _checks(
    result: CalibrationResult,
    robot: RobotDescription,
    meas: Measurements,
    opts: CalibrationOptions,
    say: Progress,
) -> None:
    """The nominal robot and the priors against the data (one more fit without priors:
    a wrong nominal table or units), and gravity-like residuals on a robot without a
    self-weight layout; their findings join the result's diagnostics. A fit beyond what
    a model file holds (another robot's data) is refused here, for a script as for the
    command (which refused it only when writing model.yaml, after the cross-validation;
    a script got it with success True)."""
    from kinecal.identification._gravity_check import gravity_check
    from kinecal.identification._mirror import mirrored_frame
    from kinecal.io._checks import lone_labels
    from kinecal.io._model_bounds import check_result

    result.diagnostics.extend(lone_labels(meas))  # issue 35: fitted to one row
    if opts.priors != "none" and meas.n <= NOMINAL_CHECK_ROWS:
        say("check", "the nominal robot and the priors against the data")
        result.diagnostics.extend(nominal_check(result, robot, meas, options=opts))
    found = gravity_check(result, meas)
    if found is not None:
        result.diagnostics.append(found)
    mirror = mirrored_frame(result, meas)
    if mirror is not None:
        raise DataError(mirror)
    try:
        check_result(result.calibrated, str(meas.source))
    except DataError as exc:
        raise DataError(
            _loose_beyond(result, opts, str(meas.source)) or str(exc)
        ) from None


def _loose_beyond(
    result: CalibrationResult, opts: CalibrationOptions, source: str
) -> str | None:
    """The fit's parameters beyond a model file's bounds that the data hardly determine
    without their priors (``loose_parameters``, or where a fit that did not converge
    drifts): a fit without the priors, not the data of another robot."""
    from kinecal.identification._options import PRIOR_GROUPS
    from kinecal.io._model_bounds import check_value

    cal = result.calibrated
    layout = cal.model.layout
    values = np.asarray(cal.params, float) * layout.to_file
    codes = ("loose_parameters", "not_converged")  # the latter: where the fit drifts
    loose = {p for d in result.diagnostics if d.code in codes for p in d.parameters}
    beyond = []
    held = PRIOR_GROUPS[opts.priors]
    for name in sorted(loose, key=layout.index):
        i = layout.index(name)
        if layout.specs[i].group in held:  # it had a prior: the data are at fault
            continue
        try:
            check_value(cal.model, i, float(values[i]), name)
        except ConfigError:
            beyond.append(f"{name} {values[i]:.6g} {layout.specs[i].unit.file_unit}")
    if not beyond:
        return None
    return (
        f"{source}: with --priors "
        f"{opts.priors}, {', '.join(beyond)} end{'s' if len(beyond) == 1 else ''} "
        "beyond what a model file holds: without a prior, these poses hardly determine "
        f"{'it' if len(beyond) == 1 else 'them'} (the data need not be wrong). Keep the "
        "priors (--priors all), or measure poses that determine "
        f"{'it' if len(beyond) == 1 else 'them'} (kinecal plan)."
    )


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


def _check_arguments(
    robot: Any,
    meas: Any,
    options: Any,
    cv_folds: Any,
    groups: Any,
    group_name: str,
) -> None:
    """What a script hands :func:`calibrate_measurements`: a robot, its measurements,
    options, a fold count and one group label per row (ConfigError otherwise); no set
    in other units than the rest (:func:`kinecal.io._checks.set_units`); the folds
    checked before the calibration runs (not after it, as a fold's failure)."""
    from kinecal.io._checks import set_units
    from kinecal.workflows._args import count, need, need_measurements, need_robot

    need_robot(robot)
    need_measurements(meas, robot.n_joints)
    set_units(meas, robot)
    if options is not None:
        need(options, CalibrationOptions, "options")
    if groups is not None and np.shape(groups) != (meas.n,):
        raise ConfigError(
            f"groups: expected one label per row of meas ({meas.n}); got shape "
            f"{np.shape(groups)}."
        )
    if cv_folds is not None:
        check_cv_folds(
            meas,
            count(cv_folds, "cv_folds", 2),
            None if groups is None else np.asarray(groups),
            group_name,
        )


def check_cv_folds(
    meas: Measurements, k: int, groups: np.ndarray | None, group_name: str | None
) -> None:
    """``--cv K``: the folds' own check (too few poses, sets or groups to hold out),
    run before the calibration rather than after it."""
    from kinecal.errors import DataError
    from kinecal.identification import make_folds

    if (
        k > meas.n
    ):  # said plainly (the folds' rule would count what is left to hold out)
        raise DataError(
            f"{meas.source}: --cv {k}: {k} folds asked, but the data have {meas.n} rows; "
            f"expected at most {meas.n} (5 or 10 is usual)."
        )
    folds = [make_folds(meas, k, groups=groups, group_name=group_name or "group")]
    if groups is None and len(meas.set_labels) > 1:  # the in-session figure's too
        folds.append(make_folds(meas, k, scheme="pose"))
    for f in folds:
        if not f.by_set:
            _check_sets_in_folds(meas, k, f.test, group_name or f.unit)


def _check_sets_in_folds(
    meas: Measurements, k: int, tests: list[np.ndarray], unit: str
) -> None:
    """Every set a fold holds rows of keeps at least 3 rows to fit its user frame on
    (a set of 3 rows, or of copies of one pose, lost them to a fold: the whole
    calibration failed after it had run, with 'set B has 2 rows')."""
    from kinecal.errors import DataError

    n_sets = len(meas.set_labels)
    total = np.bincount(meas.set_index, minlength=n_sets)
    for i, test in enumerate(tests):
        held = np.bincount(meas.set_index[test], minlength=n_sets)
        short = np.flatnonzero((held > 0) & (total - held < 3))
        if short.size:
            s = int(short[0])
            raise DataError(
                f"{meas.source}: --cv {k}: fold {i + 1} holds out {held[s]} of the "
                f"{total[s]} rows of set {meas.set_labels[s]!r} (whole {unit}s), leaving "
                f"{total[s] - held[s]} to fit its user frame on; expected at least 3 "
                f"left in every fold: more poses in that set, or --cv off."
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
