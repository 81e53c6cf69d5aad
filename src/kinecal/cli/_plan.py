"""``kinecal plan``: choose the poses to measure (issue 22)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

from kinecal.cli._common import (
    SEED,
    FiniteFloat,
    Progress,
    allow_out_of_limits_option,
    common_options,
    echo_err,
    manifest,
    option_table,
    parse_floats,
    parse_pose,
    refuse_unused,
)
from kinecal.cli._iso9283 import iso_plan_options, run_iso_plan

if TYPE_CHECKING:
    from kinecal.workflows import PlanSetup

_PRESETS = ("kinematic", "ntm", "rfcm", "full")


def _floats(text: str | None, n: int, name: str) -> list[float] | None:
    return None if text is None else parse_floats(text, n, name)


_FILE = click.Path(dir_okay=False)
_POS = FiniteFloat(0.0, low_open=True)
_INT = click.IntRange(min=1)
_ON = {"show_default": True}
# (option declarations, settings) of `kinecal plan`, in the order --help lists them.
# fmt: off
_OPTIONS: list[tuple[tuple[str, ...], dict[str, Any]]] = [
    (("--robot", "robot_name"), {"metavar": "NAME|FILE", "help": "Built-in robot or YAML."}),
    (("--candidates",), {"type": _FILE, "help": "CAND.csv: j1_deg..jN_deg of the poses "
        "the cell allows (a sensor's: optional target column)."}),
    (("--poses",), {"type": _INT, "help": "Poses to choose."}),
    (("--add", "add_n"), {"type": _INT, "help": "With --model DIR/model.yaml: poses to "
        "add to that calibration."}),
    (("--out", "out_path"), {"required": True, "type": _FILE, "help": "PLAN.csv: the "
        "chosen rows of CAND.csv, in the order to measure."}),
    (("--report", "report_path"), {"type": _FILE, "help": "report.json [default: "
        "PLAN.report.json beside --out]."}),
    (("--model", "model_name"), {"default": "full", **_ON, "metavar": "NAME|MODEL.yaml",
        "help": "kinematic, ntm, rfcm, full, or a calibrated model.yaml (with --add)."}),
    (("--instrument",), {"type": click.Choice(("tracker", "pose", "sensor")), "help":
        "Laser tracker (points), 6-D tracker, or 3D sensor and targets [default: "
        "tracker, or the model's]."}),
    (("--targets",), {"type": _FILE, "help": "Targets (target, x_mm, y_mm, z_mm; user "
        "frame): sensor."}),
    (("--noise-mm",), {"type": _POS, "help": "Per-axis noise of a measured position "
        "[mm; default 0.01, or the calibration's]."}),
    (("--noise-deg",), {"type": _POS, "default": 0.002, **_ON, "help": "Orientation "
        "noise (pose) [deg]."}),
    (("--criterion",), {"type": click.Choice(("I", "D", "A", "E", "G")), "default": "I",
        **_ON, "help": "I: mean prediction variance over the candidates; D: log det; "
        "A: trace of the covariance; E: smallest eigenvalue; G: largest prediction "
        "variance."}),
    (("--exchange",), {"type": click.Choice(("fedorov", "detmax", "none")),
        "default": "fedorov", **_ON, "help": "Improvement after the greedy choice."}),
    (("--priors",), {"type": click.Choice(("all", "compliance", "none")),
        "default": "all", **_ON, "help": "The calibration's priors (MAP)."}),
    (("--user-frame",), {"metavar": "X,Y,Z,R,W,P", "help": "Robot base in the user "
        "frame [mm, deg; Trans Rz(R) Ry(W) Rx(P)]; default identity."}),
    (("--tool",), {"metavar": "X,Y,Z[,R,W,P]", "help": "Tool (reflector, sensor) in the "
        "flange frame [mm, deg]; default the robot file's."}),
    (("--joint-range",), {"metavar": "J1:LO:HI,...", "help": "Generated candidates: "
        "joint ranges [deg] (default the limits)."}),
    (("--n-candidates",), {"type": click.IntRange(min=10), "default": 5000, **_ON,
        "help": "Candidates to generate."}),
    (("--min-j5-deg",), {"type": FiniteFloat(0.0), "default": 10.0, **_ON,
        "help": "Generated: smallest |J5| (wrist singularity)."}),
    (("--min-conditioning",), {"type": FiniteFloat(0.0, 1.0), "default": 0.05, **_ON,
        "help": "Generated: smallest inverse condition number of the geometric "
        "Jacobian."}),
    (("--floor-mm",), {"type": FiniteFloat(), "help": "Generated: lowest tool point (z in the "
        "robot base frame) [mm]."}),
    (("--station",), {"metavar": "X,Y,Z", "help": "Generated (tracker): tracker "
        "position in the user frame [mm]; the reflector must face it."}),
    (("--cone-deg",), {"type": FiniteFloat(0.0, 90.0), "default": 30.0, **_ON,
        "help": "Reflector acceptance half-angle about the tool z axis."}),
    (("--standoff-mm",), {"default": "115:135", **_ON, "metavar": "LO:HI",
        "help": "Generated (sensor): sensor-to-target distance."}),
    (("--save-candidates",), {"type": _FILE, "help": "Write the generated candidates."}),
    (("--data", "data_path"), {"type": _FILE, "help": "With --add: the calibration's "
        "data (the information of its poses is the start)."}),
    (("--random-draws",), {"type": _INT, "default": 20, **_ON, "help": "Random plans "
        "in the comparison."}),
    (("--seed",), {"type": SEED, "default": 0, **_ON, "help": "Seed of generated "
        "candidates and random plans."}),
    (("--json", "as_json"), {"is_flag": True, "help": "Print the summary as JSON."}),
    (("--force",), {"is_flag": True, "help": "Overwrite --out and the report."}),
]
# fmt: on


@click.command()
@option_table(_OPTIONS)
@iso_plan_options
@allow_out_of_limits_option
@common_options
def plan(**kw: Any) -> None:
    """Choose the poses that determine a calibration model best.

    From CAND.csv (reachable, collision-free poses of the cell: j1_deg..jN_deg) or from
    generated candidates, choose N poses that minimise the expected prediction error of
    the model (I-optimal, default) or another optimal-design criterion, order them for
    short joint motion and write them to PLAN.csv (rows copied from CAND.csv). The
    report gives the expected parameter standard deviations and held-out accuracy, and
    the same for random plans of the same size. With --iso9283: the ISO 9283 pose
    test instead (docs/iso9283.md).
    """
    if kw["iso9283"]:
        return run_iso_plan(kw, Progress(kw["quiet"]))
    _run(kw, Progress(kw["quiet"]))


def _setup(kw: dict[str, Any], say: Progress) -> PlanSetup:
    """Robot, model, design point and instrument from the options."""
    from kinecal.io import load_model, read_targets
    from kinecal.robot import load_robot
    from kinecal.workflows import plan_setup
    from kinecal.workflows._plan import (
        calibration_noise_mm,
        default_instrument,
        model_robot,
    )

    name = kw["model_name"]
    sequential = name not in _PRESETS
    if sequential and not (name.endswith((".yaml", ".yml")) or Path(name).is_file()):
        raise click.BadParameter(
            f"expected one of {', '.join(_PRESETS)} or a model.yaml; got {name!r}",
            param_hint="--model",
        )
    if sequential != (kw["add_n"] is not None) or (kw["add_n"] is None) == (
        kw["poses"] is None
    ):
        raise click.UsageError(
            "give --poses N with a model name, or --model DIR/model.yaml with --add N."
        )
    cal = load_model(name) if sequential else None
    if cal is not None:
        robot = model_robot(cal, kw["robot_name"], name)
    elif kw["robot_name"]:
        robot = load_robot(kw["robot_name"])
    else:
        raise click.UsageError("--robot is required (or --model DIR/model.yaml).")
    inst_name = kw["instrument"] or default_instrument(cal)
    noise_mm = kw["noise_mm"]
    if noise_mm is None and cal is not None:
        noise_mm, rep = calibration_noise_mm(name)
        if noise_mm:
            say("noise", f"{noise_mm:.4g} mm per axis from {rep}")
    tg = read_targets(kw["targets"]) if kw["targets"] else None
    if inst_name == "sensor" and tg is None:
        raise click.UsageError("--instrument sensor needs --targets T.csv.")
    if inst_name != "sensor" and tg is not None:  # issue 35: it was ignored
        raise click.UsageError(
            f"--targets is for --instrument sensor; --instrument {inst_name} measures "
            "the tool directly (remove --targets, or --instrument sensor)."
        )
    T = parse_pose(kw["user_frame"], "--user-frame")
    if cal is not None and (T is not None or kw["tool"]):
        raise click.UsageError("--user-frame, --tool: a calibrated model has its own.")
    T_tool = parse_pose(kw["tool"] or None, "--tool", (3, 6))
    return plan_setup(
        robot, cal if cal is not None else name, instrument=inst_name,
        noise_mm=noise_mm, noise_deg=kw["noise_deg"], targets=tg, T_user_base=T,
        T_flange_tool=T_tool, model_name=name,
    )  # fmt: skip


def _candidates(kw: dict[str, Any], setup: PlanSetup, say: Progress) -> Any:
    """Candidate poses: read from --candidates, or generated."""
    from kinecal.workflows import plan_candidates
    from kinecal.workflows._plan import joint_ranges

    _refuse_unused(kw, setup.instrument.name == "sensor")
    so: list[float] | None = [115.0, 135.0]
    st = None
    if not kw["candidates"]:
        try:
            ranges = joint_ranges(kw["joint_range"], setup.robot)
        except ValueError as exc:
            raise click.BadParameter(str(exc), param_hint="--joint-range") from None
        if setup.instrument.name == "sensor":
            try:
                so = _floats(kw["standoff_mm"].replace(":", ","), 2, "--standoff-mm")
            except click.BadParameter:
                so = None
            if so is None or not 0 < so[0] <= so[1]:
                raise click.BadParameter(
                    f"expected 0 < LO <= HI [mm]; got {kw['standoff_mm']!r}",
                    param_hint="--standoff-mm",
                )
        else:
            st = _floats(kw["station"], 3, "--station")
    assert so is not None
    return plan_candidates(
        setup, path=kw["candidates"], n=kw["n_candidates"],
        ranges=None if kw["candidates"] else ranges, seed=kw["seed"],
        min_j5_deg=kw["min_j5_deg"], min_conditioning=kw["min_conditioning"],
        floor_mm=kw["floor_mm"], station_mm=None if st is None else tuple(st),
        cone_deg=kw["cone_deg"], standoff_mm=(so[0], so[1]), progress=say,
    )  # fmt: skip


def _refuse_unused(kw: dict[str, Any], sensor: bool) -> None:
    """Options given that this plan would not use."""
    why = {n: "is for --iso9283" for n in _ISO}
    if sensor:
        why |= {"station": "is for a tracker", "cone_deg": "is for a tracker"}
    else:
        why["standoff_mm"] = "is for --instrument sensor"
    why |= {n: "is for generated candidates" for n in _GENERATED if kw["candidates"]}
    why |= {} if kw["add_n"] else {"data_path": "is for --model MODEL.yaml --add N"}
    refuse_unused(why)


_ISO = ("cube_mm", "cube_centre", "cycles", "orientation", "iso_plane")
_GENERATED = ("joint_range", "n_candidates", "min_j5_deg", "min_conditioning",
    "floor_mm", "station", "cone_deg", "standoff_mm")  # fmt: skip


def _run(kw: dict[str, Any], say: Progress) -> None:
    from kinecal.io import atomic_write_files, json_text
    from kinecal.io._files import check_distinct_outputs
    from kinecal.workflows import plan_measurements
    from kinecal.workflows._plan import read_measured_poses, report_path
    from kinecal.workflows._poses import pose_lines

    out = Path(kw["out_path"])
    rep = report_path(kw["out_path"], kw["report_path"])
    check_distinct_outputs([out, rep, kw["save_candidates"]])
    for p in (out, rep, kw["save_candidates"]):
        if p and Path(p).exists() and not kw["force"]:
            raise FileExistsError(f"{p} exists; use --force to overwrite it.")
    setup = _setup(kw, say)
    cand = _candidates(kw, setup, say)
    files: dict[str, bytes | str] = {}
    if kw["save_candidates"]:
        lines = pose_lines(setup.robot, cand.q, cand.target_index, setup.labels)
        files[kw["save_candidates"]] = "\n".join(lines) + "\n"
    measured = measured_ti = None
    if setup.cal is not None and kw["data_path"]:
        measured, measured_ti = read_measured_poses(
            setup, kw["data_path"], bool(kw["allow_out_of_limits"]), echo_err
        )
    n = kw["poses"] or kw["add_n"]
    option = "--add" if kw["add_n"] else "--poses"
    if n > cand.q.shape[0]:
        raise click.BadParameter(
            f"{n} poses asked, but there are {cand.q.shape[0]} candidates",
            param_hint=option,
        )
    run = plan_measurements(
        setup, cand, n, criterion=kw["criterion"], exchange=kw["exchange"],
        priors=kw["priors"], measured=measured, measured_target_index=measured_ti,
        data_path=kw["data_path"], random_draws=kw["random_draws"], seed=kw["seed"],
        option=option, progress=say,
    )  # fmt: skip
    doc = {
        **run.report,
        "manifest": manifest(
            {
                "candidates": kw["candidates"],
                "targets": kw["targets"],
                "data": kw["data_path"],
            },
            {k: v for k, v in kw.items() if k not in ("quiet", "force", "as_json")},
        ),
    }
    files[str(out)] = run.csv_text()
    files[str(rep)] = json_text(doc)
    saved = [kw["save_candidates"]] if kw["save_candidates"] else []
    printed = (
        [(json.dumps(run.summary(out, rep)), False)]
        if kw["as_json"]
        else run.summary_lines(out, rep, saved)
    )  # before the files: a failure leaves an earlier plan as it was (issue 35)
    atomic_write_files(files, force=kw["force"])  # all of them or none
    for line, err in printed:
        click.echo(line, err=err)
