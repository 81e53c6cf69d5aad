"""``kinecal simulate``, ``kinecal compare`` and ``kinecal demo``."""

from __future__ import annotations

import json
from pathlib import Path

import click

from kinecal.cli._common import Progress, common_options, manifest, targets_option

EXTRA_CHOICES = ("harmonics", "wrist", "masses", "thermal")


def _parse_extras(text: str | None) -> tuple[str, ...]:
    if not text:
        return ()
    out = tuple(t.strip() for t in text.split(",") if t.strip())
    for e in out:
        if e not in EXTRA_CHOICES:
            raise click.BadParameter(
                f"unknown effect {e!r}; choose from {', '.join(EXTRA_CHOICES)}",
                param_hint="--extras",
            )
    return out


def _run_experiment(
    number: int,
    seed: int,
    n_train: int,
    extras: tuple[str, ...],
    noise_um: float | None,
    outliers: float,
):
    from kinecal.simulation import LaserTracker, SphereSensor, experiment1, experiment2

    if number == 2:
        tracker = (
            LaserTracker(noise_um * 1e-6, 0.0)
            if noise_um is not None
            else LaserTracker(5e-6, 2e-6)
        )
        return experiment2(
            seed,
            n_train=n_train,
            extras=extras,
            tracker=tracker,
            outlier_fraction=outliers,
        )
    sensor = (
        SphereSensor(noise_um * 1e-6, 2 * noise_um * 1e-6)
        if noise_um is not None
        else None
    )
    return experiment1(seed, n_train=n_train, extras=extras, sensor=sensor)


def _write_experiment(exp, out: Path, force: bool) -> dict[str, str]:
    from kinecal.identification import CalibratedModel
    from kinecal.io import save_model, write_measurements, write_targets

    robot = exp.truth.robot
    files = {
        "train": str(out / "train.csv"),
        "test": str(out / "test.csv"),
        "truth": str(out / "truth.yaml"),
    }
    write_measurements(out / "train.csv", exp.train, robot, force=force)
    write_measurements(out / "test.csv", exp.test, robot, force=force)
    if exp.targets is not None:
        labels, p, r = exp.targets
        write_targets(out / "targets.csv", labels, p, r, force=force)
        files["targets"] = str(out / "targets.csv")
    import numpy as np

    tm = exp.truth.model
    truth = CalibratedModel(
        tm,
        exp.truth.params,
        np.full(tm.size, np.nan),
        ["fixed"] * tm.size,
        info={
            "truth": exp.truth.description,
            "extras": list(exp.truth.extras),
            "thermal_ppm_per_pose": exp.truth.thermal_ppm_per_pose,
            "outlier_poses": int(exp.outlier_rows.size),
        },
    )
    save_model(out / "truth.yaml", truth, force=force)
    return files


@click.command()
@click.option(
    "--experiment",
    type=click.Choice(("1", "2")),
    default="2",
    show_default=True,
    help="1: 3D sensor and four ceramic spheres; 2: laser tracker grid.",
)
@click.option(
    "--out",
    "out_dir",
    required=True,
    type=click.Path(file_okay=False),
    help="Folder for train.csv, test.csv, targets.csv, truth.yaml, manifest.json.",
)
@click.option("--seed", type=int, default=0, show_default=True, help="Random seed.")
@click.option(
    "--n-train", type=int, default=100, show_default=True, help="Poses to calibrate."
)
@click.option(
    "--extras",
    metavar="LIST",
    help="Effects outside every model: harmonics,wrist,masses,thermal.",
)
@click.option(
    "--noise-um",
    type=float,
    help="Per-axis noise [um] (default: tracker 5 um + 2 um/m; sensor 4/8 um).",
)
@click.option(
    "--outliers",
    type=float,
    default=0.0,
    show_default=True,
    help="Fraction of tracker rows with gross errors (experiment 2).",
)
@click.option("--force", is_flag=True, help="Overwrite files in --out.")
@common_options
def simulate(
    experiment: str,
    out_dir: str,
    seed: int,
    n_train: int,
    extras: str | None,
    noise_um: float | None,
    outliers: float,
    force: bool,
    quiet: bool,
) -> None:
    """Simulate one of the paper's experiments on the digital twin (LR Mate 200iD)."""
    from kinecal.io import prepare_output_dir, write_json

    say = Progress(quiet)
    out = prepare_output_dir(
        out_dir, ["train.csv", "test.csv", "truth.yaml"], force=force
    )
    ex = _parse_extras(extras)
    say("simulate", f"experiment {experiment}, seed {seed}")
    exp = _run_experiment(int(experiment), seed, n_train, ex, noise_um, outliers)
    files = _write_experiment(exp, out, force)
    write_json(
        out / "manifest.json",
        manifest(
            {},
            {
                "experiment": int(experiment),
                "seed": seed,
                "n_train": n_train,
                "extras": list(ex),
                "noise_um": noise_um,
                "outliers": outliers,
                "files": files,
                **exp.info,
            },
        ),
        force=True,
    )
    click.echo(f"{exp.name}: {exp.train.n} poses to calibrate, {exp.test.n} to test")
    for k, v in files.items():
        click.echo(f"  {k:7s} {v}")
    robot_arg = "fanuc-lrmate200id"
    tgt = f" --targets {files['targets']}" if "targets" in files else ""
    click.echo(
        f"next: kinecal compare {files['train']} {files['test']} --robot {robot_arg}{tgt}"
    )


@click.command()
@click.argument("train", type=click.Path(dir_okay=False))
@click.argument("test", type=click.Path(dir_okay=False))
@click.option(
    "--robot",
    "robot_name",
    required=True,
    metavar="NAME|FILE",
    help="Robot name or file.",
)
@targets_option
@click.option(
    "--models",
    default="kinematic,ntm,rfcm,full",
    show_default=True,
    help="Comma-separated models to fit.",
)
@click.option(
    "--refit", type=click.Choice(("user",)), help="Refit the user frame(s) on TEST."
)
@click.option(
    "--priors",
    type=click.Choice(("all", "compliance", "none")),
    default="all",
    show_default=True,
    help="Physical priors ('none': the paper's least squares).",
)
@click.option(
    "--out",
    "out_dir",
    type=click.Path(file_okay=False),
    help="Write comparison.json, report.html and one model file per method here.",
)
@click.option("--json", "as_json", is_flag=True, help="Print the table as JSON.")
@click.option("--force", is_flag=True, help="Overwrite files in --out.")
@common_options
def compare(
    train: str,
    test: str,
    robot_name: str,
    targets: str | None,
    models: str,
    refit: str | None,
    priors: str,
    out_dir: str | None,
    as_json: bool,
    force: bool,
    quiet: bool,
) -> None:
    """Fit several models on TRAIN and score each on TEST (Tables 5 and 8)."""
    from kinecal.identification import CalibrationOptions, compare_models
    from kinecal.io import read_measurements
    from kinecal.report import comparison_table, format_table
    from kinecal.robot import load_robot

    say = Progress(quiet)
    robot = load_robot(robot_name)
    names = tuple(m.strip() for m in models.split(",") if m.strip())
    for n in names:
        if n not in ("kinematic", "ntm", "rfcm", "full"):
            raise click.BadParameter(f"unknown model {n!r}", param_hint="--models")
    tr = read_measurements(train, robot, targets)
    te = read_measurements(test, robot, targets)
    rows = compare_models(
        robot,
        tr,
        te,
        names,
        options=CalibrationOptions(priors=priors),
        refit_user=refit == "user",
        progress=say,
    )
    table = comparison_table(rows)
    if out_dir:
        _write_comparison(
            Path(out_dir),
            rows,
            te,
            table,
            f"model comparison: {Path(test).name}",
            force,
            {"train": train, "test": test, "targets": targets},
        )
    if as_json:
        click.echo(json.dumps(table))
    else:
        click.echo(format_table(table))


def _write_comparison(
    out: Path,
    rows,
    test,
    table,
    title: str,
    force: bool,
    inputs: dict[str, str | None],
    notes: list[str] | None = None,
    extra_html: str = "",
) -> None:
    from kinecal.io import prepare_output_dir, save_model, write_json
    from kinecal.report import write_comparison_report

    out = prepare_output_dir(out, ["comparison.json", "report.html"], force=force)
    write_json(out / "comparison.json", table, force=True)
    for r in rows:
        if r.calibrated is not None and r.model != "nominal":
            save_model(out / f"model-{r.model}.yaml", r.calibrated, force=True)
    write_json(
        out / "manifest.json",
        manifest(inputs, {"models": [r.model for r in rows]}),
        force=True,
    )
    write_comparison_report(
        out / "report.html", rows, test, title=title, notes=notes, extra_html=extra_html
    )


@click.command()
@click.option(
    "--out",
    "out_dir",
    default="demo-results",
    show_default=True,
    type=click.Path(file_okay=False),
    help="Results folder.",
)
@click.option("--seed", type=int, default=0, show_default=True, help="Random seed.")
@click.option("--force", is_flag=True, help="Overwrite an earlier demo in --out.")
@common_options
def demo(out_dir: str, seed: int, force: bool, quiet: bool) -> None:
    """Run both of the paper's experiments on the built-in digital twin.

    Simulates the LR Mate 200iD with the paper's identified errors plus effects no model
    captures, calibrates the kinematic, NTM, RFCM and full models on 100 poses, scores
    them on the rest, checks the parameters against the hidden truth, and writes data,
    models, tables and HTML reports to --out.
    """
    from kinecal.demo import run_demo

    say = Progress(quiet)
    text = run_demo(Path(out_dir), seed=seed, force=force, progress=say)
    click.echo(text)
