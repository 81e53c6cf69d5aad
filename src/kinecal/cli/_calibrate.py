"""``kinecal calibrate`` and ``kinecal evaluate`` (file formats: docs/files.md)."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import click

from kinecal.cli._common import (
    MODEL_CHOICES,
    FiniteFloat,
    Progress,
    allow_out_of_limits_option,
    common_options,
    echo_err,
    jobs_option,
    model_file_option,
    option_table,
    parse_int_list,
    read_data_checked,
    refuse_unused,
    targets_option,
)
from kinecal.cli._iso9283 import (
    iso_evaluate_options,
    run_iso_evaluate,
)

# Folds of the held-out figure `kinecal calibrate` reports by default (issue 38).
DEFAULT_CV_FOLDS = 5
# What `kinecal calibrate` writes into --out (residuals.csv: report.RESIDUALS_CSV).
_RESULT_FILES = (
    "model.yaml",
    "report.json",
    "report.html",
    "residuals.csv",
    "manifest.json",
)


_CHOICE = click.Choice
# (option declarations, settings) of `kinecal calibrate`, in the order --help lists them.
# fmt: off
_OPTIONS: list[Any] = [
    (("--robot", "robot_name"), {"required": True, "metavar": "NAME|FILE", "help":
        "Built-in robot (see `kinecal robots`) or robot YAML file."}),
    (("--model", "model_name"), {"type": _CHOICE(MODEL_CHOICES), "default": "auto",
        "show_default": True, "help": "kinematic (paper MDH), ntm, rfcm, full (paper "
        "'Ours'), or auto: the terms the data support, chosen by cross-validation over "
        "whole regions of the workspace (whole sessions when DATA has several sets)."}),
    (("--out", "out_dir"), {"required": True, "type": click.Path(file_okay=False),
        "help": "Output folder for model.yaml, report.json, residuals.csv (per-pose "
        "errors), manifest.json and report.html."}),
    targets_option,
    (("--loss",), {"type": _CHOICE(("linear", "huber", "soft_l1")), "default": "linear",
        "show_default": True, "help": "Robust loss on whole rows (outliers are always "
        "reported)."}),
    (("--priors",), {"type": _CHOICE(("all", "compliance", "none")), "default": "all",
        "show_default": True, "help": "Physical priors (MAP): 'none' is the paper's "
        "plain least squares."}),
    (("--stage2",), {"type": _CHOICE(("direct", "project", "none")), "default": "direct",
        "show_default": True, "help": "Stage-2 Fourier fit: on position residuals, or "
        "projected to joints (Eq. 29)."}),
    (("--hayati",), {"is_flag": True, "help": "Hayati rows (no d) for joints whose axis "
        "is parallel to the next one."}),
    (("--ntm-joints",), {"metavar": "J,J,..", "help": "Joints with transmission terms "
        "[default: the three revolute joints with the longest lever to the tool: 1,2,3 "
        "on 6-axis arms]."}),
    (("--ntm-order",), {"type": click.IntRange(1, 8), "default": 2, "show_default": True,
        "help": "Order of the Fourier series (Eq. 16)."}),
    (("--report/--no-report",), {"default": True, "show_default": True, "help":
        "Write report.html with figures."}),
    (("--cv", "cv_text"), {"default": str(DEFAULT_CV_FOLDS), "show_default": True,
        "metavar": "K|off", "help": "Report K-fold cross-validated held-out errors of "
        "the chosen model (random poses, and whole sessions or regions) and of the "
        "nominal one; the summary leads with them. 'off' skips them (the summary then "
        "has the errors on the calibration data only)."}),
    (("--cv-groups", "cv_groups"), {"metavar": "COLUMN", "help": "A column of DATA whose "
        "equal values must stay in one fold of --cv and --model auto (default: rows "
        "measured at the same joints stay together; several sets are folded whole)."}),
    (("--reject",), {"type": _CHOICE(("auto", "off")), "default": "auto",
        "show_default": True, "help": "Leave out gross errors (rows far beyond the noise "
        "of the others, standing apart, not explained by the pose) and fit again "
        "without them; 'off' only reports improbable rows."}),
    (("--reject-z",), {"type": FiniteFloat(0.0, low_open=True), "default": None,
        "metavar": "Z", "help": "Reject every row beyond Z robust sigmas (whitened error "
        "over the robust noise) instead of the automatic test."}),
    (("--accept", "accept"), {"metavar": "RMS_MM[,MAX_MM]", "help": "Acceptance limits: "
        "a PASS/FAIL verdict on the held-out errors (on the calibration data when "
        "cross-validation is off) in the console, report.json ('acceptance') and "
        "report.html; the exit code does not change."}),
    (("--meta", "meta"), {"multiple": True, "metavar": "KEY=VALUE", "help": "A "
        "certificate field (repeatable): robot serial, instrument and its certificate, "
        "operator, site, standard, ...; stored in manifest.json and report.json and "
        "shown in report.html."}),
    jobs_option("Worker processes for the cross-validation of --model auto and --cv"),
    allow_out_of_limits_option,
    (("--force",), {"is_flag": True, "help": "Overwrite results already in --out."}),
]
# fmt: on


@click.command()
@click.argument("data", type=click.Path(dir_okay=False))
@option_table(_OPTIONS)
@common_options
def calibrate(
    data: str,
    robot_name: str,
    model_name: str,
    out_dir: str,
    targets: str | None,
    loss: str,
    priors: str,
    stage2: str,
    hayati: bool,
    ntm_joints: str | None,
    ntm_order: int,
    report: bool,
    cv_text: str,
    cv_groups: str | None,
    reject: str,
    reject_z: float | None,
    accept: str | None,
    meta: tuple[str, ...],
    jobs: int,
    allow_out_of_limits: bool,
    force: bool,
    quiet: bool,
) -> None:
    """Identify a robot (and sensor) model from measurements DATA.csv.

    DATA has controller angles j1_deg..jN_deg and either x_mm, y_mm, z_mm (tracker
    points, optionally with qw..qz) or target, xc_mm, yc_mm, zc_mm (sensor, with
    --targets). Calibration starts from the nominal robot; no guess is needed.
    Exit code 3 when the fit does not converge (results are still written).
    """
    from kinecal._parallel import available_cpus
    from kinecal.cli._errors import ExitCode, ResultsWithError
    from kinecal.identification import CalibrationOptions
    from kinecal.io import prepare_output_dir
    from kinecal.report._certificate import certificate_block, temperature_range
    from kinecal.robot import load_robot
    from kinecal.workflows import calibrate_measurements
    from kinecal.workflows._calibrate import (
        calibration_files,
        group_labels,
        write_calibration,
    )

    meta_fields, cv_folds, limits = _checked_options(meta, cv_text, accept)
    refuse_unused(_unused(model_name, cv_folds, reject))
    say = Progress(quiet)
    jobs = jobs or available_cpus()
    robot = load_robot(robot_name)
    # The result folder first: a clash or an unwritable --out stops the run at once.
    out = prepare_output_dir(out_dir, list(_RESULT_FILES), force=force)
    say.begin("data", f"reading {data}")
    meas, data_checks = read_data_checked(data, robot, targets, allow_out_of_limits)
    say("data", f"{meas.n} {meas.kind} rows from {data}")
    opts = CalibrationOptions(
        loss=loss, priors=priors, stage2=stage2, reject=reject, reject_z=reject_z
    )
    groups = group_labels(data, cv_groups, meas.rows) if cv_groups else None
    if cv_folds is not None:  # the folds' own check, before the calibration runs
        cv_folds = _usable_folds(meas, cv_folds, groups, cv_groups)
    certificate = certificate_block(meta_fields, temperature_range(data, meas.rows))
    nj = _transmission_joints(ntm_joints, robot)
    run = calibrate_measurements(
        robot, meas, model=model_name, options=opts, hayati=hayati, ntm_joints=nj,
        ntm_order=ntm_order, cv_folds=cv_folds, groups=groups,
        group_name=cv_groups or "group", jobs=jobs, progress=say,
    )  # fmt: skip
    _fold_warnings(run.held_out)
    files = calibration_files(
        run, meas, data_checks=data_checks, certificate=certificate, limits=limits
    )
    settings = {
        "model": model_name, "loss": loss, "priors": priors, "stage2": stage2,
        "hayati": list(run.hayati), "ntm_joints": list(nj), "ntm_order": ntm_order,
        "cv": cv_folds, "cv_groups": cv_groups, "reject": reject,
        "reject_z": reject_z, "accept": accept,
    }  # fmt: skip
    inputs = {"data": data, "targets": targets, "robot": robot_name}
    written = write_calibration(
        out, run, files, inputs, settings, meta_fields, report, say
    )
    if report:
        say("report", f"wrote {Path(out_dir) / 'report.html'}")
    _print_summary(run, files, limits is not None)
    click.echo(f"wrote     {Path(out_dir)}{os.sep}: {', '.join(written)}")
    if not run.result.success:  # the summary, then one Error line last (issue 35)
        raise ResultsWithError(
            ExitCode.NOT_CONVERGED,
            f"the calibration did not converge; its results are in {Path(out_dir)}"
            f"{os.sep}, flagged (report.json 'success': false): {_NOT_CONVERGED}",
        )


_NOT_CONVERGED = (
    "see the warnings above and the report's stages; more or better-spread poses, or "
    "a smaller --model"
)


def _fold_warnings(held: Any) -> None:
    """The cross-validation's notes on its folds, once each, as warnings."""
    if held is not None:
        for note in dict.fromkeys(n for fig in held.figures for n in fig.folds.notes):
            click.echo(f"warning   {note}", err=True)


def _checked_options(
    meta: tuple[str, ...], cv_text: str, accept: str | None
) -> tuple[dict[str, str], int | None, tuple[float, float | None] | None]:
    """``--meta``, ``--cv`` and ``--accept`` parsed: (fields, folds, limits)."""
    from kinecal.report._acceptance import parse_accept
    from kinecal.report._certificate import parse_meta

    try:
        meta_fields = parse_meta(meta)
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint="--meta") from None
    cv_folds = _cv_folds(cv_text)
    limits = None
    if accept is not None:
        try:
            limits = parse_accept(accept)
        except ValueError as exc:
            raise click.BadParameter(str(exc), param_hint="--accept") from None
    return meta_fields, cv_folds, limits


_NTM = ("ntm_joints", "ntm_order", "stage2")


def _unused(model: str, cv: int | None, reject: str) -> dict[str, str]:
    """The options a calibration with these settings would not use, and why."""
    why = {} if reject == "auto" else {"reject_z": "is for --reject auto"}
    if model in ("kinematic", "rfcm"):  # no transmission terms
        why |= dict.fromkeys(_NTM, "is for --model ntm, full or auto")
    if cv is None and model != "auto":
        why["cv_groups"] = "is for --cv K or --model auto"
    return why


def _usable_folds(meas: Any, k: int, groups: Any, cv_groups: str | None) -> int | None:
    """``--cv K`` checked on the data; the default K that does not fit them: None,
    with a note (no held-out figure, said so)."""
    from kinecal.errors import DataError
    from kinecal.workflows._calibrate import check_cv_folds

    try:
        check_cv_folds(meas, k, groups, cv_groups)
    except DataError as exc:
        given = click.get_current_context().get_parameter_source("cv_text")
        if given is not None and given.name not in ("DEFAULT", "DEFAULT_MAP"):
            raise  # an explicit --cv K (even the default's K) the data cannot give
        click.echo(f"note      no cross-validation: {exc}", err=True)
        return None
    return k


def _transmission_joints(text: str | None, robot: Any) -> tuple[int, ...]:
    """``--ntm-joints`` (default: the robot's), each a revolute joint."""
    nj = parse_int_list(text, "--ntm-joints", robot.n_joints) or robot.ntm_joints
    revolute = [i + 1 for i, j in enumerate(robot.joints) if j.kind != "prismatic"]
    bad = [j for j in nj if j not in revolute]
    if bad:
        raise click.BadParameter(
            f"joint {bad[0]} is not a revolute joint of {robot.name} (a transmission "
            f"series needs one); its revolute joints: {', '.join(map(str, revolute))}.",
            param_hint="--ntm-joints",
        )
    return tuple(nj)


def _print_summary(run: Any, files: Any, accept: bool) -> None:
    """The console summary: model, accuracy (held-out first), before, notes, verdict,
    identifiability notes; the result's warnings on stderr."""
    from kinecal.report._acceptance import verdict_line
    from kinecal.report._headline import accuracy_lines

    result, summary = run.result, files.summary
    b = result.metrics_before
    click.echo(
        f"model     {run.spec.name}: {result.identifiability.rank} of "
        f"{result.calibrated.model.size} parameters estimated"
    )
    # the figure the user will get first: held-out (when it ran), then the fit's own
    for line in accuracy_lines(summary["accuracy"]):
        click.echo(line)
    click.echo(
        f"before    RMS {b.rms_mm:.4f} mm  max {b.max_mm:.4f} mm  (nominal, frames fitted)"
    )
    if run.held_out is not None:
        for note in run.held_out.notes:
            click.echo(f"note      {note}")
    if accept:
        click.echo(f"accept    {verdict_line(summary['acceptance'])}")
    for line in result.identifiability.summary()[1:]:
        click.echo(f"note      {line}")
    for w in result.warnings:
        click.echo(f"warning   {w}", err=True)


def _cv_folds(text: str) -> int | None:
    """``--cv K|off`` -> K (>= 2) or None."""
    if text.strip().lower() == "off":
        return None
    try:
        k = int(text)
    except ValueError:
        k = 0
    if k < 2:
        raise click.BadParameter(
            f"expected a number of folds >= 2 or 'off'; got {text!r}.",
            param_hint="--cv",
        )
    return k


def _refit_groups(text: str | None) -> tuple[str, ...]:
    """``--refit user,tool`` as a tuple; a bad word (or none) is a usage error."""
    if text is None:
        return ()
    words = tuple(w.strip() for w in text.split(",") if w.strip())
    bad = [w for w in words if w not in ("user", "tool", "marker")]
    if bad or not words:
        raise click.BadParameter(
            f"takes 'user', 'tool' and 'marker', comma-separated; got {text!r}.",
            param_hint="--refit",
        )
    return tuple(dict.fromkeys(words))


# fmt: off
_EVALUATE_OPTIONS: list[Any] = [
    model_file_option,
    targets_option,
    (("--refit",), {"metavar": "WHAT[,WHAT]", "help": "Re-estimate on DATA first: "
        "'user' (the user frames: a new instrument set-up), 'tool' (the tool frame: a "
        "re-mounted probe or reflector nest), 'marker' (each marker's offset); e.g. "
        "--refit user,tool."}),
    (("--json", "as_json"), {"is_flag": True, "help": 'Print {"n", "rms_mm", "std_mm", '
        '"mean_mm", "max_mm"} (with --iso9283: {"iso9283": ...}).'}),
    (("--errors-out",), {"type": click.Path(dir_okay=False), "help": "Write per-row "
        "errors (row, ex_mm, ey_mm, ez_mm, err_mm) to this CSV."}),
    iso_evaluate_options,
    allow_out_of_limits_option,
    (("--force",), {"is_flag": True, "help": "Overwrite --errors-out (and --out)."}),
]
# fmt: on


@click.command()
@click.argument("data", type=click.Path(dir_okay=False))
@option_table(_EVALUATE_OPTIONS)
@common_options
def evaluate(
    data: str,
    model_path: str,
    targets: str | None,
    refit: str | None,
    as_json: bool,
    errors_out: str | None,
    iso9283: bool,
    iso_out: str | None,
    allow_out_of_limits: bool,
    force: bool,
    quiet: bool,
) -> None:
    """Accuracy of a calibrated model on measurements DATA.csv (held-out poses).

    With --iso9283: the ISO 9283 figures of a pose test (docs/iso9283.md)."""
    from kinecal.io import atomic_write_files, load_model
    from kinecal.workflows import evaluate_measurements

    if iso_out and not iso9283:  # the arguments' checks before the work
        raise click.UsageError("--out is for --iso9283.")
    what = _refit_groups(refit)
    if errors_out and Path(errors_out).exists() and not force:
        raise FileExistsError(f"{errors_out}: exists; use --force to overwrite it.")
    say = Progress(quiet)  # lines only for stages that last (a large file)
    cal = load_model(model_path)
    say.begin("data", f"reading {data}")
    # ISO 9283: one tool orientation over a small cube by design, not a finding
    skip = ("poor_excitation",) if iso9283 else ()
    robot = cal.model.robot
    meas, _ = read_data_checked(data, robot, targets, allow_out_of_limits, skip)
    say.begin("evaluate", f"{meas.n} rows")
    run = evaluate_measurements(
        cal, meas, refit=what, data_name=data, model_name=model_path, say=echo_err
    )
    errors = {errors_out: run.errors_csv()} if errors_out else {}
    if iso9283:  # --errors-out written with the ISO figures, once they are in
        return run_iso_evaluate(
            cal, run.meas, data, what, iso_out, force, as_json, model_path, errors
        )
    m = run.evaluation.metrics  # what it prints, before the file (issue 35)
    lines = [json.dumps(m.contract())] if as_json else run.summary_lines()
    atomic_write_files(errors, force=force)
    click.echo("\n".join(lines))
