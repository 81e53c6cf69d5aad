"""The evaluation workflow of ``kinecal evaluate``: a calibrated model's accuracy on
held-out measurements, after re-estimating the user, tool or marker frames if asked."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from kinecal.errors import DataError
from kinecal.identification import Evaluation
from kinecal.measurement import CalibratedModel, Measurements
from kinecal.robot import RobotDescription
from kinecal.workflows._seeds import OTHER_ROBOT_MM

__all__ = ["OTHER_ROBOT_MM", "ModelEvaluation", "evaluate_measurements"]


Say = Callable[[str], None]


@dataclass(frozen=True)
class ModelEvaluation:
    """What :func:`evaluate_measurements` found.

    Attributes
    ----------
    evaluation : the errors (metrics, per row) and the model used (after a refit).
    meas : the measurements, aligned with the model's sets and markers.
    refit : what was re-estimated first.
    messages : the warnings found on the way (data against the model, the refit).
    """

    evaluation: Evaluation = field(repr=False)
    meas: Measurements = field(repr=False)
    refit: tuple[str, ...] = ()
    messages: tuple[str, ...] = ()

    def errors_csv(self) -> str:
        """Per-row errors: ``row, ex_mm, ey_mm, ez_mm, err_mm`` (``--errors-out``)."""
        ev = self.evaluation
        lines = ["row,ex_mm,ey_mm,ez_mm,err_mm"]
        for r, e, d in zip(self.meas.rows, ev.error_xyz_mm, ev.errors_mm):
            lines.append(f"{r},{e[0]:.6f},{e[1]:.6f},{e[2]:.6f},{d:.6f}")
        return "\n".join(lines) + "\n"

    def summary_lines(self) -> list[str]:
        """The console summary of ``kinecal evaluate``: poses (and what was refitted),
        the error statistics, per axis, and the orientation errors of pose data."""
        m = self.evaluation.metrics
        what = f"  (refitted: {', '.join(self.refit)})" if self.refit else ""
        lines = [
            f"poses  {m.n}{what}",
            f"RMS    {m.rms_mm:.4f} mm   Std {m.std_mm:.4f}   Avg {m.mean_mm:.4f}   "
            f"Max {m.max_mm:.4f} mm",
            "axes   RMS x {:.4f}  y {:.4f}  z {:.4f} mm".format(*m.rms_xyz_mm),
        ]
        if m.rot_rms_deg is not None:
            lines.append(
                f"orient RMS {m.rot_rms_deg:.4f} deg   Max {m.rot_max_deg:.4f} deg"
            )
        return lines


def evaluate_measurements(
    cal: CalibratedModel,
    meas: Measurements,
    *,
    refit: tuple[str, ...] = (),
    data_name: str | None = None,
    model_name: str = "the model",
    say: Say | None = None,
) -> ModelEvaluation:
    """The accuracy of ``cal`` on ``meas`` as ``kinecal evaluate`` finds it: the data
    checked against the model (sets, markers, joint ranges), ``refit`` (any of 'user',
    'tool', 'marker') re-estimated on ``meas`` first, then the errors.

    ``data_name``, ``model_name``: the files, for messages; ``say`` gets each warning
    line as it is found (they are also in ``messages``).

    Returns
    -------
    ModelEvaluation
        The errors and the measurements they are for.

    Raises
    ------
    DataError
        Data of another robot, frame or set-up (median error over 50 mm).
    IdentifiabilityError
        A set with fewer than 3 distinct poses to refit its frames on, or a marker the
        model lacks (fitted with --refit marker or tool) with fewer than 3.
    """
    from kinecal.identification import evaluate
    from kinecal.io import check_data_for_model
    from kinecal.io._checks import set_units
    from kinecal.workflows._args import need_measurements, need_model, words

    need_model(cal)
    need_measurements(meas, cal.model.robot.n_joints)
    refit = words(refit, ("user", "tool", "marker"), "refit")
    lines: list[str] = []

    def emit(line: str) -> None:
        lines.append(line)
        if say is not None:
            say(line)

    header = _header(data_name)
    set_units(meas, cal.model.robot)
    meas, found = check_data_for_model(meas, cal)
    check_payload_column(
        meas.payload_kg, meas.rows, cal.model.robot, data_name or meas.source
    )
    if meas.payload_kg is not None:  # as compensate's TARGETS and --payload-kg
        from kinecal.workflows._compensate import check_payload_scales

        check_payload_scales(cal, f"{data_name or meas.source}: column 'payload_kg'")
    else:
        said = _payload_assumed(cal)
        if said:
            emit(f"note      {data_name or meas.source}: {said}")
    if {"marker", "tool"} & set(refit):  # a marker of one row: its refit matches it
        from kinecal.io._checks import lone_labels

        found = [*found, *lone_labels(meas, ("marker",))]
    for d in found:
        if d.severity == "warning":
            emit(f"warning   {d.message}")
    note = _training_data(data_name, model_name) or _own_residuals(
        data_name, header, model_name
    )
    if note:
        emit(f"warning   {note}")
    check_refit_poses(meas, refit)
    ev = evaluate(cal, meas, refit=refit)
    _refuse_compensated(data_name, header, ev.metrics.max_mm)
    _check_same_robot(
        ev.errors_mm, data_name or meas.source, model_name, cal.model.robot.name,
        _radian_like(meas, cal),
    )  # fmt: skip
    for d in ev.diagnostics:
        if d.severity == "warning":
            emit(f"warning   {d.message}")
    hint = _setup_changed(cal, meas, refit, ev.metrics.rms_mm)
    if hint:
        emit(f"warning   {data_name or meas.source}: {hint}")
    return ModelEvaluation(ev, meas, refit, tuple(lines))


# A set-up change is looked for above this RMS [mm] (a calibrated robot's held-out
# error is below it), and named when refitting frames cuts the RMS this many times.
SETUP_MM = 0.1
_SETUP_FACTOR = 3.0
_MEANS = {
    "user": "the instrument or the part moved",
    "tool": "the tool, probe or reflector nest re-mounted",
}


def _setup_changed(
    cal: CalibratedModel, meas: Measurements, refit: tuple[str, ...], rms_mm: float
) -> str | None:
    """The frames whose refit on ``meas`` cuts its RMS ``_SETUP_FACTOR`` times (the
    fewest that do, a larger set only where it does 1.2x better): errors of a set-up
    that differs from the calibration's, printed as the robot's accuracy unsaid."""
    import warnings

    from kinecal.errors import CalibError
    from kinecal.identification import evaluate

    if not rms_mm > SETUP_MM:
        return None
    best: tuple[tuple[str, ...], float] | None = None
    for extra in (("tool",), ("user",), ("user", "tool")):
        what = tuple(dict.fromkeys((*refit, *extra)))
        if set(what) == set(refit):
            continue
        try:
            check_refit_poses(meas, what)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                got = evaluate(cal, meas, refit=what).metrics.rms_mm
        except (CalibError, ValueError, np.linalg.LinAlgError):
            continue
        if got * _SETUP_FACTOR < rms_mm and (best is None or got * 1.2 < best[1]):
            best = (what, got)
    if best is None:
        return None
    what, got = best
    new = [w for w in what if w not in refit]
    return (
        f"refitting the {' and '.join(new)} frame{'s' if len(new) > 1 else ''} on these "
        f"rows brings the RMS from {rms_mm:.4f} to {got:.4f} mm: the set-up differs "
        f"from the calibration's ({'; '.join(_MEANS[w] for w in new)}?). These errors "
        f"are the set-up's, not the robot's; for a new session: --refit {','.join(what)}."
    )


def check_payload_column(
    payload_kg: np.ndarray | None, lines: Any, robot: RobotDescription, path: str
) -> None:
    """A ``payload_kg`` column (of evaluate's data or compensate's TARGETS) up to 10 x
    the robot's rated payload, as ``--payload-kg`` and a calibration's reference
    payload (3000 kg on a 5 kg arm was a warning, and scored or compensated with exit
    0); between the rating and that, a warning says so."""
    from kinecal.io._model_bounds import payload_limit

    if payload_kg is None:
        return
    hi, also = payload_limit(robot)
    over = np.flatnonzero(np.asarray(payload_kg, float) > hi)
    if over.size:
        i = int(over[0])
        raise DataError(
            f"{path}: line {lines[i]}, column 'payload_kg': {payload_kg[i]:g} kg "
            f"({over.size} rows over); expected at most {hi:g} kg{also} for "
            f"{robot.name}: a unit mistake (g, lb)?"
        )


def _payload_assumed(cal: CalibratedModel) -> str | None:
    """What data without a ``payload_kg`` column are scored at, for a model whose
    payload compliance has a reference payload (the calibration's); None for models
    whose predictions do not depend on the payload."""
    ref = cal.reference_payload_kg
    if not cal.model.spec.load or ref is None:
        return None
    return (
        f"no payload_kg column: every pose is scored at the calibration's reference "
        f"payload ({ref:g} kg); add the column where the payload differs."
    )


def _training_data(data: str | None, model_path: str) -> str | None:
    """The data file is the very file the model was calibrated on (its SHA-256 is the
    one manifest.json beside the model records): its figures are training errors,
    printed as if held out."""
    from pathlib import Path

    from kinecal.io import file_sha256
    from kinecal.io._json_read import loads

    if data is None:
        return None
    try:
        man = loads((Path(model_path).parent / "manifest.json").read_text())
        sha = man["inputs"]["data"]["sha256"]
        same = isinstance(sha, str) and file_sha256(data) == sha
    except (OSError, ValueError, KeyError, TypeError):
        return None
    if not same:
        return None
    return (
        f"{data}: the very data {model_path} was calibrated on (manifest.json beside it "
        "has its SHA-256): these are training errors, not held-out ones (report.json "
        "has them); evaluate on poses the model was not fitted on."
    )


def _radian_like(meas: Measurements, cal: CalibratedModel) -> bool:
    """Every revolute joint value within +-2 pi degrees: radians under jK_deg columns
    (the reader tells them by their spread from 5 rows on)."""
    rev = ~np.asarray(cal.model.robot.prismatic)
    return bool(
        rev.any() and np.abs(meas.q_ctrl[:, rev]).max() <= np.radians(2 * np.pi)
    )


def _check_same_robot(
    errors_mm: np.ndarray, data: str, model_path: str, robot: str, radians: bool
) -> None:
    med = float(np.median(errors_mm)) if len(errors_mm) else 0.0
    if med > OTHER_ROBOT_MM:
        raise DataError(
            f"{data}: the model's median error on these rows is {med:.1f} mm (expected "
            f"at most {OTHER_ROBOT_MM:g} mm for any calibrated robot): are they "
            f"measurements of {robot}, the robot of {model_path}, in the frame and "
            "set-up it was calibrated in? (--refit user,tool for a new set-up)"
            + (
                f" Every joint value is within ±{2 * np.pi:.2f} deg: radians in jK_deg "
                "columns? (convert to degrees or name the columns jK_rad)"
                if radians
                else ""
            )
        )


def check_refit_poses(meas: Measurements, what: tuple[str, ...]) -> None:
    """``evaluate --refit``: refuse a set whose rows hold fewer than 3 distinct poses
    (copies of one pose let the refitted frames absorb every error: an RMS of zero)."""
    from kinecal._stats import distinct_rows
    from kinecal.errors import IdentifiabilityError

    if not what:
        return
    cols = [meas.q_ctrl, meas.marker_index[:, None]]
    if meas.target_index is not None:
        cols.append(meas.target_index[:, None])
    key = np.hstack(cols)
    labels = meas.set_labels or ("",)
    for s, label in enumerate(labels):
        rows = meas.set_index == s
        distinct = distinct_rows(key[rows])
        if rows.sum() >= 3 and distinct < 3:
            name = f"set {label!r}" if label else "the data"
            raise IdentifiabilityError(
                f"{meas.source}: {name}: its {int(rows.sum())} rows hold only {distinct} "
                f"distinct pose{'s' if distinct != 1 else ''} (rows repeat the same "
                f"joint angles); --refit {','.join(what)} needs at least 3 different "
                "poses per set (or no --refit)."
            )


def _header(data: str | None) -> set[str]:
    """The column names of the data file (its first line that is not a comment)."""
    import re

    if data is None:
        return set()
    try:
        with open(data, encoding="utf-8-sig", errors="replace") as f:
            head = next((s for s in f if s.strip() and not s.startswith("#")), "")
    except OSError:
        return set()
    return {c.strip().strip('"') for c in re.split(r"[,;\t]", head)}


# Below this largest error [mm] the positions are the model's own (no instrument
# measures a robot to a micrometre over a session): compensate's targets, met to 1e-3 mm.
MODEL_OWN_MM = 1e-3


def _refuse_compensated(data: str | None, cols: set[str], max_mm: float) -> None:
    """DATA is a ``compensate`` output (CORRECTED.csv: the targets with the corrected
    joints, ``jK_deg_program``, ``err_mm``, ``status``) as written, not measurements:
    its positions are the targets, which the model meets by construction (``evaluate``
    printed an RMS of 3e-8 mm as the robot's accuracy). Measured positions pasted into
    it (the corrected program measured) are evaluated."""
    import re

    program = sorted(c for c in cols if re.fullmatch(r"j\d+_(deg|mm|rad|m)_program", c))
    if program and {"err_mm", "status"} <= cols and max_mm < MODEL_OWN_MM:
        raise DataError(
            f"{data}: columns {program[0]}.., err_mm, status: a file kinecal compensate "
            "wrote (the targets with the corrected joints), not measurements: its "
            f"x_mm, y_mm, z_mm are the targets, which the model meets by construction "
            f"(largest error {max_mm:.1e} mm); expected the positions measured with "
            "the robot at these joints."
        )


def _own_residuals(data: str | None, cols: set[str], model_path: str) -> str | None:
    """DATA is the residuals.csv beside the model (``calibrate``'s per-pose errors):
    its rows are the calibration's own poses, so its figures are training errors (the
    manifest's check of the data file does not see this copy)."""
    from pathlib import Path

    if data is None or not {"err_before_mm", "err_mm"} <= cols:
        return None
    model = Path(model_path)
    if not model.is_file() or Path(data).resolve().parent != model.resolve().parent:
        return None
    return (
        f"{data}: the residuals {model_path}'s calibration wrote (err_before_mm, "
        "err_mm): its rows are the poses the model was fitted on, so these are "
        "training errors, not held-out ones; evaluate on poses the model was not "
        "fitted on."
    )
