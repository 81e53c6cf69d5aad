"""``kinecal simulate``, ``kinecal compare`` and ``kinecal demo``."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import click

from kinecal.cli._common import (
    SEED,
    FiniteFloat,
    Progress,
    common_options,
    manifest,
    option_table,
    parse_pose,
    refuse_unused,
    targets_option,
)

EXTRA_CHOICES = ("harmonics", "wrist", "masses", "thermal")
_SIM_FILES = ("train.csv", "test.csv", "targets.csv", "truth.yaml", "manifest.json")
COMPARE_FILES = ("comparison.json", "model-*.yaml", "report.html", "manifest.json")


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
) -> Any:
    from kinecal.workflows import simulate_paper_experiment

    try:
        return simulate_paper_experiment(
            number,
            seed=seed,
            n_train=n_train,
            extras=extras,
            noise_um=noise_um,
            outliers=outliers,
        )
    except ValueError as exc:  # the pose count is known once the poses are planned
        if str(exc).startswith("n_train must be"):
            n_max = str(exc).split(" and ", 1)[1].split(";", 1)[0]
            raise click.BadParameter(
                f"experiment {number} plans {int(n_max) + 1} poses and keeps at least "
                f"one to test; expected 1 to {n_max}; got {n_train}",
                param_hint="--n-train",
            ) from None
        raise


@click.command()
@click.option(
    "--experiment",
    type=click.Choice(("1", "2")),
    default=None,
    help="1: 3D sensor and four ceramic spheres; 2: laser tracker grid (the default). "
    "The paper's LR Mate 200iD twin.",
)
@click.option(
    "--robot",
    "robot_name",
    metavar="NAME|FILE",
    help="A twin of this robot (built-in, YAML or URDF) instead of the paper's: random "
    "tolerances, zero offsets, gravity compliance from its self-weight layout or link "
    "masses, a laser tracker; also writes robot.yaml.",
)
@click.option(
    "--plan",
    "plan_file",
    type=click.Path(exists=True, dir_okay=False),
    help="With --robot: measure these poses (j1_deg..jN_deg, e.g. from `kinecal plan`) "
    "for train.csv instead of --n-train random ones.",
)
@click.option(
    "--n-test",
    type=click.IntRange(min=1),
    default=300,
    show_default=True,
    help="With --robot: random poses to test.",
)
@click.option(
    "--tool",
    metavar="X,Y,Z[,R,W,P]",
    help="With --robot: the reflector in the flange frame [mm, deg] (default the "
    "robot file's tool), as for `kinecal plan --tool`.",
)
@click.option(
    "--new-session",
    is_flag=True,
    help="With --robot: measure test.csv from a second tracker station (evaluate it "
    "with --refit user).",
)
@click.option(
    "--sensor",
    is_flag=True,
    help="With --robot: a 3D sensor on the flange (the cam frame: --tool, or 35 mm "
    "beside and 75 mm out) sees four spheres (targets.csv), as experiment 1 does.",
)
@click.option(
    "--payload-kg",
    type=FiniteFloat(0.0),
    help="With --robot: payload at the tool [kg] (default the robot's, or a 1 kg tool); "
    "written as a payload_kg column.",
)
@click.option(
    "--out",
    "out_dir",
    required=True,
    type=click.Path(file_okay=False),
    help="Folder for train.csv, test.csv, targets.csv, truth.yaml, manifest.json.",
)
@click.option("--seed", type=SEED, default=0, show_default=True, help="Random seed.")
@click.option(
    "--n-train",
    type=click.IntRange(min=1),
    default=100,
    show_default=True,
    help="Poses to calibrate (the rest are the test set).",
)
@click.option(
    "--extras",
    metavar="LIST",
    help="Effects outside every model: harmonics,wrist,masses,thermal.",
)
@click.option(
    "--noise-um",
    type=FiniteFloat(0.0),
    help="Per-axis noise [um] (default: tracker 5 um + 2 um/m; sensor 4/8 um).",
)
@click.option(
    "--outliers",
    type=FiniteFloat(0.0, 1.0),
    default=0.0,
    show_default=True,
    help="Fraction (0 to 1) of tracker rows with gross errors of 1-3 mm "
    "(experiment 2 only).",
)
@click.option("--force", is_flag=True, help="Overwrite files in --out.")
@common_options
def simulate(
    experiment: str | None,
    robot_name: str | None,
    plan_file: str | None,
    n_test: int,
    tool: str | None,
    new_session: bool,
    sensor: bool,
    payload_kg: float | None,
    out_dir: str,
    seed: int,
    n_train: int,
    extras: str | None,
    noise_um: float | None,
    outliers: float,
    force: bool,
    quiet: bool,
) -> None:
    """Simulate a paper's experiment on the LR Mate 200iD twin, or any robot (--robot).

    Writes train.csv and test.csv (measurements), targets.csv (experiment 1), truth.yaml
    (the true robot as a model file, for `kinecal evaluate` or a parameter comparison),
    robot.yaml (--robot: the robot file to calibrate with) and manifest.json; all of
    them or none (the folder is written at the end).
    """
    from kinecal.io import prepare_output_dir
    from kinecal.workflows._simulate import write_simulation

    if robot_name is not None:
        if experiment is not None or outliers > 0:
            raise click.BadParameter(
                "--robot simulates a laser-tracker (or with --sensor a 3D-sensor) "
                "calibration of that robot; expected no --experiment or --outliers "
                "with it",
                param_hint="--robot",
            )
        _simulate_robot(
            robot_name,
            out_dir,
            seed,
            n_train,
            n_test,
            plan_file,
            payload_kg,
            tool,
            new_session,
            sensor,
            _parse_extras(extras),
            noise_um,
            force,
            quiet,
        )
        return
    _robot_only(plan_file, payload_kg, new_session, tool, sensor)
    experiment = experiment or "2"

    if experiment == "1" and outliers > 0:
        raise click.BadParameter(
            "experiment 1 (sensor) has no gross-error model; expected 0 with "
            f"--experiment 1; got {outliers:g}",
            param_hint="--outliers",
        )
    say = Progress(quiet)
    ex = _parse_extras(extras)
    out = prepare_output_dir(out_dir, list(_SIM_FILES), force=force)
    say("simulate", f"experiment {experiment}, seed {seed}")
    sim = _run_experiment(int(experiment), seed, n_train, ex, noise_um, outliers)
    files = write_simulation(sim, out, Path(out_dir))
    config: dict[str, Any] = {
        "experiment": int(experiment),
        "seed": seed,
        "n_train": n_train,
    }
    config |= {"extras": list(ex), "noise_um": noise_um, "outliers": outliers}
    tgt = f" --targets {files['targets']}" if "targets" in files else ""
    _finish(
        out, out_dir, sim, files, {}, config,
        f"next: kinecal compare {files['train']} {files['test']} --robot "
        f"fanuc-lrmate200id{tgt}",
    )  # fmt: skip


def _robot_only(
    plan_file: str | None,
    payload_kg: float | None,
    new_session: bool,
    tool: str | None,
    sensor: bool = False,
) -> None:
    """Refuse the options of a twin of a robot without --robot."""
    for name, value in (
        ("--plan", plan_file),
        ("--payload-kg", payload_kg),
        ("--new-session", new_session or None),
        ("--sensor", sensor or None),
        ("--tool", tool),
    ):
        if value is not None:
            raise click.BadParameter(
                f"{name} is for a twin of a robot; expected it with --robot",
                param_hint=name,
            )


def _finish(
    out: Path,
    out_dir: str,
    sim: Any,
    files: dict[str, str],
    inputs: dict[str, str | None],
    config: dict[str, Any],
    next_line: str,
) -> None:
    """Write manifest.json and print what was written and what to run next."""
    from kinecal.io import write_json

    exp = sim.experiment
    write_json(
        out / "manifest.json",
        manifest(
            inputs,
            {**config, "files": files, **exp.info},
            files=[Path(f).name for f in files.values()],
        ),
        force=True,
    )
    click.echo(f"{exp.name}: {exp.train.n} poses to calibrate, {exp.test.n} to test")
    for k, v in {**files, "manifest": str(Path(out_dir) / "manifest.json")}.items():
        click.echo(f"  {k:8s} {v}")
    click.echo(next_line)


def _simulate_robot(
    robot_name: str,
    out_dir: str,
    seed: int,
    n_train: int,
    n_test: int,
    plan_file: str | None,
    payload_kg: float | None,
    tool: str | None,
    new_session: bool,
    sensor: bool,
    extras: tuple[str, ...],
    noise_um: float | None,
    force: bool,
    quiet: bool,
) -> None:
    """``simulate --robot``: a twin of that robot measured by a laser tracker (or a
    3D sensor, ``--sensor``)."""
    from dataclasses import replace

    from kinecal.io import prepare_output_dir
    from kinecal.robot import load_robot
    from kinecal.workflows import read_pose_file, simulate_robot_twin
    from kinecal.workflows._simulate import write_simulation

    say = Progress(quiet)
    robot = load_robot(robot_name)
    if payload_kg is not None:
        robot = replace(robot, payload_kg=payload_kg or None)
    if tool is not None:
        robot = replace(robot, T_flange_tool=parse_pose(tool, "--tool", (3, 6)))
    if plan_file:  # its rows are the poses to calibrate (--n-train was ignored)
        refuse_unused({"n_train": f"is for random poses; --plan {plan_file} has them"})
    q_train = read_pose_file(plan_file, robot, None)[2] if plan_file else None
    if sensor and (plan_file or new_session):
        raise click.BadParameter(
            "--sensor plans its own views of the spheres in one session; expected no "
            "--plan or --new-session with it",
            param_hint="--sensor",
        )
    files = ["train.csv", "test.csv", "truth.yaml", "robot.yaml", "manifest.json"]
    files += ["targets.csv"] if sensor else []
    out = prepare_output_dir(out_dir, files, force=force)
    say("simulate", f"{robot.name}, seed {seed}")
    sim = simulate_robot_twin(
        robot, seed=seed, n_train=n_train, n_test=n_test, q_train=q_train,
        extras=extras, noise_um=noise_um, new_session=new_session, sensor=sensor,
    )  # fmt: skip
    exp = sim.experiment
    written = write_simulation(sim, out, Path(out_dir), sim.robot, plan_file)
    config: dict[str, Any] = {"seed": seed, "n_train": exp.train.n}
    config |= {"n_test": exp.test.n, "extras": list(extras), "noise_um": noise_um}
    config |= {"payload_kg": robot.payload_kg, "truth": sim.description}
    config |= {"instrument": "sensor" if sensor else "tracker"}
    tgt = f" --targets {written['targets']}" if "targets" in written else ""
    _finish(
        out, out_dir, sim, written, {"robot": robot_name, "plan": plan_file}, config,
        f"next: kinecal calibrate {written['train']} --robot {written['robot']}{tgt} "
        f"--out CAL; kinecal evaluate {written['test']} --model CAL/model.yaml{tgt}",
    )  # fmt: skip


# fmt: off
_COMPARE_OPTIONS: list[Any] = [
    (("--robot", "robot_name"), {"required": True, "metavar": "NAME|FILE",
        "help": "Robot name or file."}),
    targets_option,
    (("--models",), {"default": "kinematic,ntm,rfcm,full", "show_default": True,
        "help": "Comma-separated models to fit."}),
    (("--refit",), {"type": click.Choice(("user",)), "help": "Refit the user frame(s) on "
        "TEST."}),
    (("--priors",), {"type": click.Choice(("all", "compliance", "none")),
        "default": "all", "show_default": True, "help": "Physical priors ('none': the "
        "paper's least squares)."}),
    (("--out", "out_dir"), {"type": click.Path(file_okay=False), "help": "Write "
        "comparison.json, report.html and one model file per method here."}),
    (("--json", "as_json"), {"is_flag": True, "help": "Print the table as JSON."}),
    (("--force",), {"is_flag": True, "help": "Overwrite files in --out."}),
]
# fmt: on


@click.command()
@click.argument("train", type=click.Path(dir_okay=False))
@click.argument("test", type=click.Path(dir_okay=False))
@option_table(_COMPARE_OPTIONS)
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
    from kinecal.io import prepare_output_dir, read_measurements
    from kinecal.robot import load_robot
    from kinecal.workflows import compare_measurements
    from kinecal.workflows._compare import MODELS, write_comparison

    say = Progress(quiet)
    names = tuple(m.strip() for m in models.split(",") if m.strip())
    for n in names:
        if n not in MODELS:
            raise click.BadParameter(
                f"unknown model {n!r}; expected some of {', '.join(MODELS)}",
                param_hint="--models",
            )
    if not names:
        raise click.BadParameter(
            f"expected some of {', '.join(MODELS)}; got {models!r}",
            param_hint="--models",
        )
    robot = load_robot(robot_name)
    # The result folder first: a clash or an unwritable --out stops the run at once.
    out = (
        prepare_output_dir(out_dir, list(COMPARE_FILES), force=force)
        if out_dir
        else None
    )
    tr = read_measurements(train, robot, targets)
    te = read_measurements(test, robot, targets)
    cmp = compare_measurements(
        robot, tr, te, names, priors=priors, refit_user=refit == "user", progress=say
    )
    written = []
    if out is not None:
        say("report", "writing comparison.json, the models and report.html")
        inputs = {"train": train, "test": test, "targets": targets}
        written = write_comparison(
            out,
            cmp,
            f"model comparison: {Path(test).name}",
            lambda files: manifest(
                inputs, {"models": [r.model for r in cmp.rows]}, files=files
            ),
        )
    click.echo(json.dumps(cmp.table) if as_json else cmp.text())
    if written:
        click.echo(
            f"wrote     {Path(out_dir or '')}{os.sep}: {', '.join(written)}",
            err=as_json,
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
@click.option("--seed", type=SEED, default=0, show_default=True, help="Random seed.")
@click.option("--force", is_flag=True, help="Replace an earlier demo in --out.")
@common_options
def demo(out_dir: str, seed: int, force: bool, quiet: bool) -> None:
    """Run both of the paper's experiments on the built-in digital twin.

    Simulates the LR Mate 200iD with the paper's identified errors plus effects no model
    captures, calibrates the kinematic, NTM, RFCM and full models on 100 poses, scores
    them on the rest, checks the parameters against the hidden truth, and writes data,
    models, tables and HTML reports to --out.
    """
    from kinecal.workflows import paper_demo

    say = Progress(quiet)
    click.echo(paper_demo(Path(out_dir), seed=seed, force=force, progress=say).text)
