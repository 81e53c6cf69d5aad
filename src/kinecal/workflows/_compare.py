"""The comparison workflow of ``kinecal compare`` (the paper's Tables 5 and 8): several
models fitted on one measurement set and scored on another."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from kinecal.errors import DataError
from kinecal.identification import ComparisonRow
from kinecal.measurement import Measurements
from kinecal.robot import RobotDescription

__all__ = [
    "MODELS",
    "CalibrationComparison",
    "ModelComparison",
    "compare_calibration_folders",
    "compare_measurements",
    "write_comparison",
]

# The models a comparison can fit.
MODELS = ("kinematic", "ntm", "rfcm", "full")

Progress = Callable[[str, str], None]


@dataclass(frozen=True)
class ModelComparison:
    """What :func:`compare_measurements` found.

    Attributes
    ----------
    rows : per model (the nominal one first), its calibration and held-out figures.
    table : the comparison as ``comparison.json`` holds it (mm).
    test : the measurements the models were scored on.
    """

    rows: tuple[ComparisonRow, ...]
    table: list[dict[str, Any]] = field(repr=False)
    test: Measurements = field(repr=False)

    def text(self) -> str:
        """The table as ``kinecal compare`` prints it."""
        from kinecal.report import format_table

        return format_table(self.table)


def compare_measurements(
    robot: RobotDescription,
    train: Measurements,
    test: Measurements,
    models: Sequence[str] = MODELS,
    *,
    priors: str = "all",
    refit_user: bool = False,
    progress: Progress | None = None,
) -> ModelComparison:
    """Fit each of ``models`` on ``train`` and score it on ``test``, as ``kinecal
    compare`` does (``priors``: all, compliance or none; ``refit_user``: refit the user
    frames on ``test``, a new instrument set-up).

    Returns
    -------
    ModelComparison
        Per model its calibration and held-out figures, and the table.

    Raises
    ------
    ValueError
        A model that is not one of :data:`MODELS`, or none.
    """
    from kinecal.identification import CalibrationOptions, compare_models
    from kinecal.report import comparison_table
    from kinecal.workflows._args import need_measurements, need_robot, words

    need_robot(robot)
    need_measurements(train, robot.n_joints, "train")
    need_measurements(test, robot.n_joints, "test")
    names = words(models, MODELS, "models")
    if not names:
        raise ValueError(f"models: expected some of {', '.join(MODELS)}; got none.")
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:  # fitted and listed twice, the table's rows indistinguishable
        raise DataError(
            f"--models: {twice[0]!r} given twice; expected each model once."
        )
    _check_test_not_train(train, test)
    rows = compare_models(
        robot,
        train,
        test,
        names,
        options=CalibrationOptions(priors=priors),
        refit_user=refit_user,
        progress=progress,
    )
    from kinecal.io._model_bounds import check_result

    for r in rows:  # a fit of another robot's data: refused, not scored
        if r.calibrated is not None and r.model != "nominal":
            check_result(r.calibrated, str(train.source))
    _check_test_scores(rows, train, test, robot)
    return ModelComparison(tuple(rows), comparison_table(rows), test)


def _check_test_not_train(train: Measurements, test: Measurements) -> None:
    """TEST the very rows of TRAIN (poses and measurements): its 'held-out' figures
    would be training errors."""
    import numpy as np

    same = train.n == test.n and train.p.shape == test.p.shape
    if (
        same
        and np.array_equal(train.q_ctrl, test.q_ctrl)
        and np.array_equal(train.p, test.p)
    ):
        raise DataError(
            f"{test.source}: the same rows as TRAIN {train.source}; expected "
            "measurements the models were not fitted on (a held-out test set)."
        )


def _check_test_scores(
    rows: Sequence[ComparisonRow],
    train: Measurements,
    test: Measurements,
    robot: RobotDescription,
) -> None:
    """Every calibrated model off by more than any calibration on TEST: another robot's
    data, or another frame (as ``kinecal evaluate`` refuses it)."""
    from kinecal.workflows._evaluate import OTHER_ROBOT_MM

    fitted = [r.test.mean_mm for r in rows if r.model != "nominal"]
    if fitted and min(fitted) > OTHER_ROBOT_MM:
        raise DataError(
            f"{test.source}: the models fitted on {train.source} are off by "
            f"{min(fitted):.1f} mm (mean) on these rows; expected at most "
            f"{OTHER_ROBOT_MM:g} mm: are they measurements of {robot.name} in the "
            "frame and set-up of TRAIN? (--refit user for a new set-up)"
        )


def write_comparison(
    out: Path,
    comparison: ModelComparison,
    title: str,
    manifest: Callable[[list[str]], dict[str, Any]],
) -> list[str]:
    """Write a comparison's files into the prepared folder ``out``: comparison.json,
    model-<name>.yaml, report.html and manifest.json (``manifest(files)`` gives its
    content); return their names."""
    from kinecal.io import save_model, write_json
    from kinecal.report import write_comparison_report

    rows = comparison.rows
    written = ["comparison.json"]
    write_json(out / "comparison.json", comparison.table, force=True)
    for r in rows:
        if r.calibrated is not None and r.model != "nominal":
            save_model(out / f"model-{r.model}.yaml", r.calibrated, force=True)
            written.append(f"model-{r.model}.yaml")
    write_comparison_report(
        out / "report.html", list(rows), comparison.test, title=title
    )
    written += ["report.html", "manifest.json"]
    write_json(out / "manifest.json", manifest(written[:-1]), force=True)
    return written


@dataclass(frozen=True)
class CalibrationComparison:
    """What :func:`compare_calibration_folders` found (``kinecal report --compare``).

    Attributes
    ----------
    result : the parameters that moved beyond their combined uncertainty and each
        model's accuracy on the other's data (:func:`kinecal.report._compare.
        compare_calibrations`).
    """

    result: dict[str, Any] = field(repr=False)

    def html(self) -> str:
        """compare.html."""
        from kinecal.report._compare import render_comparison

        return render_comparison(self.result)

    def lines(self) -> list[str]:
        """The console summary: what moved, then each model on the other's data."""
        c = self.result
        out = [
            f"moved     {len(c['moved'])} of {len(c['parameters'])} parameters beyond "
            f"{c['significance']:g} combined std"
            + (f": {', '.join(_shown(c, c['moved']))}" if c["moved"] else "")
        ]
        for r in c["cross"]:
            label = f"{r['model']} model on {r['data']} data"
            if "skipped" in r:
                out.append(f"accuracy  {label}: not computed ({r['skipped']})")
            else:
                out.append(
                    f"accuracy  {label}: RMS {r['rms_mm']:.4f} mm  max "
                    f"{r['max_mm']:.4f} mm"
                    + ("  (user frame refitted)" if r["refit_user"] else "")
                )
        return out


def _shown(c: dict[str, Any], names: list[str]) -> list[str]:
    """Parameter names with the robot's joint name beside them where it has one."""
    jn = {p["name"]: p.get("joint_name") for p in c["parameters"]}
    return [f"{n} ({jn[n]})" if jn.get(n) else n for n in names]


def compare_calibration_folders(
    old_dir: str | Path, new_dir: str | Path
) -> CalibrationComparison:
    """Two calibrations of one robot (folders written by ``kinecal calibrate``)
    compared: parameters that moved beyond their combined uncertainty, each model's
    accuracy on the other's data (when the manifests' data files are still there)."""
    from kinecal.report._compare import compare_calibrations
    from kinecal.workflows._report import note_folder_inputs

    for folder in (old_dir, new_dir):
        note_folder_inputs(Path(folder))
    return CalibrationComparison(compare_calibrations(old_dir, new_dir))
