"""``kinecal plan``: choose the poses to measure (issue 22)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import click

from kinecal.cli._common import (
    SEED,
    FiniteFloat,
    Progress,
    allow_out_of_limits_option,
    common_options,
)
from kinecal.cli._iso9283 import iso_plan_options, run_iso_plan
from kinecal.cli._plan_report import echo_summary, plan_report

_PRESETS = ("kinematic", "ntm", "rfcm", "full")


def _floats(text: str | None, n: int, name: str) -> list[float] | None:
    if text is None:
        return None
    try:
        vals = [float(t) for t in text.split(",")]
    except ValueError:
        vals = []
    if len(vals) != n or not all(math.isfinite(v) for v in vals):
        raise click.BadParameter(
            f"expected {n} comma-separated numbers; got {text!r}", param_hint=name
        )
    return vals


def _joint_ranges(text: str | None, robot: Any) -> Any:
    """``J1:-60:60,J3:0:90`` -> (n, 2) [rad], the limits where not given."""
    import numpy as np

    if text is None:
        return None
    r = robot.limits.copy()
    for item in text.split(","):
        parts = item.strip().split(":")
        try:
            if len(parts) != 3 or parts[0][:1].upper() != "J":
                raise ValueError
            j = int(parts[0][1:])
            lo, hi = float(parts[1]), float(parts[2])
            if not 1 <= j <= robot.n_joints or not lo <= hi:
                raise ValueError
        except ValueError:
            raise click.BadParameter(
                f"expected Jk:low:high with 1 <= k <= {robot.n_joints} and low <= high "
                f"(degrees, or mm for a prismatic joint); got {item!r}",
                param_hint="--joint-range",
            ) from None
        f = 1e-3 if robot.joints[j - 1].kind == "prismatic" else np.pi / 180
        r[j - 1] = (lo * f, hi * f)
    return r


def _read_poses(
    path: str, robot: Any, labels: tuple[str, ...] | None, allow: bool | None = None
) -> Any:
    """Joint columns (and a sensor's ``target``) of a pose file: (table, cols, q, ti).

    Candidates (``allow`` None) must lie within the limits; measured poses may pass them
    by 1 deg (1 mm), and further with ``allow`` (--allow-out-of-limits: a warning)."""
    import re

    import numpy as np

    from kinecal.errors import DataError
    from kinecal.io import read_table

    t = read_table(path)
    pat = re.compile(r"^j(\d+)_(deg|rad|mm|m)$")
    found = {int(m.group(1)): c for c in t.header if (m := pat.match(c))}
    n = robot.n_joints
    if sorted(found) != list(range(1, n + 1)):
        have = ", ".join(found[k] for k in sorted(found)) or "none"
        raise DataError(
            f"{path}: joint columns {have}; robot {robot.name} needs j1_deg .. j{n}_deg."
        )
    cols = [found[k] for k in range(1, n + 1)]
    q = np.empty((len(t.rows), n))
    lim = robot.limits
    for k, c in enumerate(cols):
        unit = c.rsplit("_", 1)[1]
        prismatic = robot.joints[k].kind == "prismatic"
        if prismatic != (unit in ("mm", "m")):
            want = f"j{k + 1}_mm" if prismatic else f"j{k + 1}_deg"
            raise DataError(f"{path}: column '{c}': joint {k + 1} needs {want}.")
        f = {"deg": np.pi / 180, "rad": 1.0, "mm": 1e-3, "m": 1.0}[unit]
        q[:, k] = t.numbers(c) * f
        slack = 1e-9 if allow is None else (1e-3 if prismatic else np.pi / 180)
        bad = np.flatnonzero(
            (q[:, k] < lim[k, 0] - slack) | (q[:, k] > lim[k, 1] + slack)
        )
        if bad.size and allow:
            click.echo(
                f"warning   {path}: {bad.size} rows with {c} beyond the limits of "
                f"{robot.name} (first: line {t.lines[bad[0]]}), accepted as asked.",
                err=True,
            )
        elif bad.size:
            i = int(bad[0])
            g = 1.0 / f
            raise DataError(
                f"{path}: line {t.lines[i]}, column '{c}': {q[i, k] * g:.6g} is outside "
                f"the joint limits [{lim[k, 0] * g:.6g}, {lim[k, 1] * g:.6g}] of "
                f"{robot.name}"
                + ("." if allow is None else " (use --allow-out-of-limits to accept).")
            )
    deg = [k for k, c in enumerate(cols) if c.endswith("_deg")]
    if deg and len(t.rows) >= 5:
        vals = np.degrees(q[:, deg])
        if np.abs(vals).max() <= 2 * np.pi + 1e-9 and np.ptp(vals, axis=0).max() > 0.05:
            raise DataError(
                f"{path}: columns {cols[deg[0]]}..{cols[deg[-1]]}: every value is within "
                f"±{2 * np.pi:.2f}, which looks like radians; convert to degrees or name "
                "the columns jK_rad."
            )
    ti = None
    if labels is not None and "target" in t.header:
        index = {lab: i for i, lab in enumerate(labels)}
        names = [s.strip() for s in t.column("target")]
        for lab, line in zip(names, t.lines):
            if lab not in index:
                raise DataError(
                    f"{path}: line {line}, column 'target': {lab!r} is not in the "
                    f"targets file ({', '.join(labels)})."
                )
        ti = np.array([index[s] for s in names], np.intp)
    return t, cols, q, ti


def _report_path(out: str, report: str | None) -> Path:
    if report:
        return Path(report)
    p = Path(out)
    return p.with_name(p.stem + ".report.json")


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


def _options(f: Any) -> Any:
    for decls, settings in reversed(_OPTIONS):
        f = click.option(*decls, **settings)(f)
    return f


@click.command()
@_options
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


def _setup(kw: dict[str, Any], say: Progress) -> dict[str, Any]:
    """Robot, model, design point and instrument from the options."""
    import numpy as np

    from kinecal.errors import ConfigError
    from kinecal.geometry import euler_transform
    from kinecal.io import load_model, read_targets
    from kinecal.planning import Instrument, planning_model
    from kinecal.robot import load_robot

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
        robot = cal.model.robot
        if kw["robot_name"] and load_robot(kw["robot_name"]).name != robot.name:
            raise ConfigError(
                f"--robot {kw['robot_name']}, but {name} was calibrated for "
                f"{robot.name}: a model and a robot of different kinds."
            )
    elif kw["robot_name"]:
        robot = load_robot(kw["robot_name"])
    else:
        raise click.UsageError("--robot is required (or --model DIR/model.yaml).")
    kind_of = {"point": "tracker", "pose": "pose", "sensor": "sensor"}
    inst_name = kw["instrument"] or (
        kind_of.get(str(cal.info.get("kind")), "tracker") if cal else "tracker"
    )
    noise_mm = kw["noise_mm"]
    if noise_mm is None and cal is not None:
        rep = Path(name).with_name("report.json")
        if rep.is_file():
            noise_mm = json.loads(rep.read_text()).get("noise_sigma_mm")
            if noise_mm:
                say("noise", f"{noise_mm:.4g} mm per axis from {rep}")
    noise_mm = float(noise_mm or 0.01)
    tg = read_targets(kw["targets"]) if kw["targets"] else None
    if inst_name == "sensor" and tg is None:
        raise click.UsageError("--instrument sensor needs --targets T.csv.")
    if inst_name != "sensor" and tg is not None:  # issue 35: it was ignored
        raise click.UsageError(
            f"--targets is for --instrument sensor; --instrument {inst_name} measures "
            "the tool directly (remove --targets, or --instrument sensor)."
        )
    inst = Instrument(
        inst_name,
        noise_mm * 1e-3,
        np.radians(kw["noise_deg"]),
        None if tg is None else tg.p,
    )
    uf = _floats(kw["user_frame"], 6, "--user-frame")
    if cal is not None:
        if uf is not None or kw["tool"]:
            raise click.UsageError(
                "--user-frame, --tool: a calibrated model has its own."
            )
        cm, x = cal.model, cal.params
        if (inst.kind == "point") == cm.spec.cam_rotation:
            raise ConfigError(
                f"{name}: the model was calibrated from "
                f"{cal.info.get('kind') or ('sensor or pose' if cm.spec.cam_rotation else 'point')}"
                " data; "
                f"--instrument {inst_name} measures other quantities."
            )
    else:
        T = T_tool = None
        if uf is not None:
            T = euler_transform([*np.array(uf[:3]) * 1e-3, *np.radians(uf[3:])])
        if kw["tool"]:
            tool = _floats(kw["tool"], len(kw["tool"].split(",")), "--tool")
            if tool is None or len(tool) not in (3, 6):
                raise click.BadParameter(
                    "expected X,Y,Z or X,Y,Z,R,W,P", param_hint="--tool"
                )
            tool = tool + [0.0] * (6 - len(tool))
            T_tool = euler_transform(
                [*np.array(tool[:3]) * 1e-3, *np.radians(tool[3:])]
            )
        cm, x = planning_model(robot, name, inst, T, T_tool)
    return {
        "robot": robot,
        "cal": cal,
        "model": cm,
        "params": x,
        "inst": inst,
        "targets": tg,
    }


def _candidates(
    kw: dict[str, Any], env: dict[str, Any], say: Progress
) -> dict[str, Any]:
    """Candidate poses: read from --candidates, or generated."""
    import numpy as np

    from kinecal.planning import joint_candidates, sensor_candidates

    robot, inst, tg = env["robot"], env["inst"], env["targets"]
    labels = None if tg is None else tg.labels
    if kw["candidates"]:
        table, _, q, ti = _read_poses(kw["candidates"], robot, labels)
        say("candidates", f"{q.shape[0]} poses from {kw['candidates']}")
        return {
            "q": q,
            "ti": ti,
            "table": table,
            "source": kw["candidates"],
            "info": {},
        }
    ranges = _joint_ranges(kw["joint_range"], robot)
    common = {
        "ranges": ranges,
        "seed": kw["seed"],
        "min_j5": np.radians(kw["min_j5_deg"]),
        "min_conditioning": kw["min_conditioning"],
        "floor_z": None if kw["floor_mm"] is None else kw["floor_mm"] * 1e-3,
    }
    say("candidates", f"generating {kw['n_candidates']} ({inst.name})")
    if inst.name == "sensor":
        try:
            so = _floats(kw["standoff_mm"].replace(":", ","), 2, "--standoff-mm")
        except click.BadParameter:
            so = None
        if so is None or not 0 < so[0] <= so[1]:
            raise click.BadParameter(
                f"expected 0 < LO <= HI [mm]; got {kw['standoff_mm']!r}",
                param_hint="--standoff-mm",
            )
        c = sensor_candidates(
            env["model"],
            env["params"],
            inst.targets,
            kw["n_candidates"],
            standoff=(so[0] * 1e-3, so[1] * 1e-3),
            **common,
        )
    else:
        st = _floats(kw["station"], 3, "--station")
        c = joint_candidates(
            env["model"],
            env["params"],
            kw["n_candidates"],
            station=None if st is None else np.array(st) * 1e-3,
            cone=np.radians(kw["cone_deg"]),
            **common,
        )
    if c.q_ctrl.shape[0] < 1:
        from kinecal.errors import DataError

        why = ", ".join(f"{v} {k}" for k, v in c.rejected.items() if v)
        raise DataError(
            f"--n-candidates {kw['n_candidates']}: no acceptable candidate among "
            f"{c.tried} poses drawn ({why}); expected looser --joint-range, "
            "--min-j5-deg, --min-conditioning, --floor-mm, --station or --cone-deg."
        )
    info = {"generated": True, "tried": c.tried, "rejected": c.rejected}
    return {
        "q": c.q_ctrl,
        "ti": c.target_index,
        "table": None,
        "source": "generated",
        "info": info,
    }


def _check_distinct(cand: dict[str, Any], n: int, option: str) -> None:
    """Refuse a plan of ``n`` poses from fewer distinct candidates (copies of one pose
    would be chosen again and again)."""
    import numpy as np

    from kinecal._stats import distinct_rows
    from kinecal.errors import DataError

    key = cand["q"] if cand["ti"] is None else np.column_stack([cand["q"], cand["ti"]])
    distinct = distinct_rows(key)
    if distinct < n:
        src = cand["source"]
        where = (
            f"{src}: the {key.shape[0]} rows hold"
            if src != "generated"
            else f"the {key.shape[0]} generated candidates (--joint-range) hold"
        )
        raise DataError(
            f"{where} only {distinct} distinct pose{'s' if distinct != 1 else ''}, but "
            f"{option} {n} asks for {n}; expected at least {n} different candidate poses."
        )


def _pose_lines(robot: Any, q: Any, ti: Any, labels: Any) -> list[str]:
    import numpy as np

    cols = [
        f"j{k + 1}_mm" if j.kind == "prismatic" else f"j{k + 1}_deg"
        for k, j in enumerate(robot.joints)
    ]
    f = np.array([1e3 if j.kind == "prismatic" else 180 / np.pi for j in robot.joints])
    lines = [",".join(cols + (["target"] if ti is not None else []))]
    for i, row in enumerate(q * f):
        cells = [f"{v:.6f}" for v in row] + ([labels[ti[i]]] if ti is not None else [])
        lines.append(",".join(cells))
    return lines


def _run(kw: dict[str, Any], say: Progress) -> None:
    from kinecal.io import atomic_write_files, json_text
    from kinecal.planning import plan_poses

    out = Path(kw["out_path"])
    rep = _report_path(kw["out_path"], kw["report_path"])
    for p in (out, rep, kw["save_candidates"]):
        if p and Path(p).exists() and not kw["force"]:
            raise FileExistsError(f"{p} exists; use --force to overwrite it.")
    env = _setup(kw, say)
    cand = _candidates(kw, env, say)
    robot, cal, inst = env["robot"], env["cal"], env["inst"]
    labels = None if env["targets"] is None else env["targets"].labels
    files: dict[str, bytes | str] = {}
    if kw["save_candidates"]:
        lines = _pose_lines(robot, cand["q"], cand["ti"], labels)
        files[kw["save_candidates"]] = "\n".join(lines) + "\n"
    measured = measured_ti = None
    if cal is not None and kw["data_path"]:
        table, _, measured, measured_ti = _read_poses(
            kw["data_path"], robot, labels, bool(kw["allow_out_of_limits"])
        )
        if {"x_mm", "xc_mm"} & set(table.header):  # measurements: checked as such
            from kinecal.io import read_measurements

            read_measurements(
                kw["data_path"],
                robot,
                env["targets"],
                allow_out_of_limits=bool(kw["allow_out_of_limits"]),
                check=False,
            )
    n = kw["poses"] or kw["add_n"]
    if n > cand["q"].shape[0]:
        raise click.BadParameter(
            f"{n} poses asked, but there are {cand['q'].shape[0]} candidates",
            param_hint="--add" if kw["add_n"] else "--poses",
        )
    _check_distinct(cand, n, "--add" if kw["add_n"] else "--poses")
    say("plan", f"{n} of {cand['q'].shape[0]} poses, {kw['criterion']}-optimal")
    pl = plan_poses(
        env["model"],
        env["params"],
        cand["q"],
        n,
        inst,
        criterion=kw["criterion"],
        exchange=kw["exchange"],
        priors=kw["priors"],
        target_index=cand["ti"],
        calibrated=cal is not None,
        measured=measured,
        measured_target_index=measured_ti,
        calibrated_std=None if cal is None else cal.std,
        random_draws=kw["random_draws"],
        seed=kw["seed"],
    )
    if cand["table"] is not None:
        t = cand["table"]
        lines = [",".join(t.header)] + [",".join(t.rows[i]) for i in pl.index]
        rows = [int(t.lines[i]) for i in pl.index]
    else:
        lines = _pose_lines(robot, pl.q_ctrl, pl.target_index, labels)
        rows = [int(i) + 1 for i in pl.index]
    doc = plan_report(pl, kw, env, cand, rows)
    files[str(out)] = "\n".join(lines) + "\n"
    files[str(rep)] = json_text(doc)
    atomic_write_files(files, force=kw["force"])  # all of them or none
    saved = [kw["save_candidates"]] if kw["save_candidates"] else []
    echo_summary(doc, out, rep, kw["as_json"], saved)
