"""The planning workflow of ``kinecal plan``: the model and instrument of a plan, the
candidates (read or generated), the poses chosen, ordered and reported (in mm, deg)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from kinecal.errors import ConfigError, DataError
from kinecal.io import Table, Targets
from kinecal.measurement import CalibratedModel
from kinecal.models import CalibrationModel
from kinecal.planning import Instrument, Plan
from kinecal.planning._candidates import range_inside_limits
from kinecal.robot import RobotDescription
from kinecal.workflows._args import need_robot, plan_arguments
from kinecal.workflows._poses import check_calibration_data, pose_lines, read_pose_file

__all__ = [
    "PlanRun",
    "PlanSetup",
    "PoseCandidates",
    "plan_candidates",
    "plan_measurements",
    "plan_setup",
]

PRESETS = ("kinematic", "ntm", "rfcm", "full")

Progress = Callable[[str, str], None]
Say = Callable[[str], None]


def _quiet(stage: str, detail: str = "") -> None:
    """No progress display."""


@dataclass(frozen=True)
class PlanSetup:
    """What a plan is for.

    Attributes
    ----------
    robot : the robot.
    model, params : the model and the parameters the design is evaluated at (the
        calibrated ones for a sequential plan).
    instrument : what measures each pose, and how well.
    cal : the calibration a sequential plan adds poses to (None: a new plan).
    targets : a sensor's targets in the user frame.
    model_name : the model's name, or the model file of a sequential plan.
    """

    robot: RobotDescription
    model: CalibrationModel = field(repr=False)
    params: np.ndarray = field(repr=False)
    instrument: Instrument
    cal: CalibratedModel | None = field(default=None, repr=False)
    targets: Targets | None = field(default=None, repr=False)
    model_name: str = "full"

    @property
    def labels(self) -> tuple[str, ...] | None:
        """The targets' labels (sensor), else None."""
        return None if self.targets is None else self.targets.labels


def plan_setup(
    robot: RobotDescription,
    model: str | CalibratedModel = "full",
    *,
    instrument: str | None = None,
    noise_mm: float | None = None,
    noise_deg: float = 0.002,
    targets: Targets | None = None,
    T_user_base: np.ndarray | None = None,
    T_flange_tool: np.ndarray | None = None,
    model_name: str | None = None,
) -> PlanSetup:
    """The model, design point and instrument of a plan for ``robot``.

    ``model``: kinematic, ntm, rfcm, full (the nominal robot with typical compliance)
    or a calibrated model (a sequential plan: poses to add to its calibration, at its
    parameters, with its user and tool frames). ``instrument``: tracker, pose or sensor
    (default: tracker, or the model's); ``noise_mm`` per axis (default 0.01), ``targets``
    a sensor's.

    Returns
    -------
    PlanSetup
        The robot, model, design point and instrument.

    Raises
    ------
    ConfigError
        A calibrated model whose data were of another kind than the instrument's.
    """
    from kinecal.planning import planning_model

    need_robot(robot)
    cal = model if isinstance(model, CalibratedModel) else None
    inst_name = instrument or default_instrument(cal)
    inst = Instrument(
        inst_name,
        float(noise_mm or 0.01) * 1e-3,
        np.radians(noise_deg),
        None if targets is None else targets.p,
    )
    if cal is not None:
        name = model_name or "model.yaml"
        cm, x = cal.model, cal.params
        if (inst.kind == "point") == cm.spec.cam_rotation:
            raise ConfigError(
                f"{name}: the model was calibrated from "
                f"{cal.info.get('kind') or ('sensor or pose' if cm.spec.cam_rotation else 'point')}"
                " data; "
                f"--instrument {inst_name} measures other quantities."
            )
    else:
        assert isinstance(model, str)
        name = model_name or model
        cm, x = planning_model(robot, model, inst, T_user_base, T_flange_tool)
    return PlanSetup(robot, cm, x, inst, cal, targets, name)


def default_instrument(cal: CalibratedModel | None) -> str:
    """The instrument of a plan without ``--instrument``: the one a calibrated model's
    data came from (tracker, pose or sensor), else a laser tracker."""
    kind_of = {"point": "tracker", "pose": "pose", "sensor": "sensor"}
    return kind_of.get(str(cal.info.get("kind")), "tracker") if cal else "tracker"


def model_robot(
    cal: CalibratedModel, robot_name: str | None, model_name: str
) -> RobotDescription:
    """The robot of a calibrated model, which ``--robot`` (when given) must name."""
    from kinecal.robot import load_robot

    robot = cal.model.robot
    if robot_name and load_robot(robot_name).name != robot.name:
        raise ConfigError(
            f"--robot {robot_name}, but {model_name} was calibrated for "
            f"{robot.name}: a model and a robot of different kinds."
        )
    return robot


def joint_ranges(text: str | None, robot: RobotDescription) -> np.ndarray | None:
    """``J1:-60:60,J3:0:90`` (deg, mm for a prismatic joint) -> (n, 2) [rad, m], the
    limits where not given; None stays None. ValueError with what is expected."""
    if text is None:
        return None
    r = robot.limits.copy()
    seen: dict[int, str] = {}  # joint -> its item
    for item in text.split(","):
        parts = item.strip().split(":")
        try:
            if len(parts) != 3 or parts[0][:1].upper() != "J":
                raise ValueError
            j = int(parts[0][1:])
            lo, hi = float(parts[1]), float(parts[2])
            if not 1 <= j <= robot.n_joints or not lo <= hi or j in seen:
                raise ValueError
            seen[j] = item  # which of two ranges of a joint is meant?
        except ValueError:
            raise ValueError(
                f"expected Jk:low:high with 1 <= k <= {robot.n_joints}, each joint once, "
                f"low <= high (degrees, or mm for a prismatic joint); got {item!r}"
            ) from None
        f = 1e-3 if robot.joints[j - 1].kind == "prismatic" else np.pi / 180
        range_inside_limits(robot, j, lo * f, hi * f, item.strip())
        r[j - 1] = (lo * f, hi * f)
    return r


def calibration_noise_mm(model_file: str) -> tuple[float | None, Path]:
    """The noise per axis [mm] that the calibration of ``model_file`` found (its
    report.json beside it), and that file; None when there is none."""
    from kinecal.io._json_read import loads

    rep = Path(model_file).with_name("report.json")
    if not rep.is_file():
        return None, rep
    try:
        noise = loads(rep.read_text())["noise_sigma_mm"]
        if noise is not None and not 0 < float(noise) < 1e3:  # nan too
            raise ValueError(noise)
    except (ValueError, TypeError, KeyError) as exc:  # an edited or damaged file
        raise DataError(
            f"{rep}: no noise_sigma_mm a calibration writes ({type(exc).__name__}: "
            f"{exc}); expected the report.json of {model_file}'s calibration (or give "
            "--noise-mm)."
        ) from None
    return (None if noise is None else float(noise)), rep


def read_measured_poses(
    setup: PlanSetup, path: str, allow: bool = False, warn: Say | None = None
) -> tuple[np.ndarray, np.ndarray | None]:
    """The poses (N, n) [rad] and target indices of a sequential plan's calibration data
    ``path`` (``--data``), checked as measurements (``allow``: beyond the limits)."""
    table, _, q, ti = read_pose_file(path, setup.robot, setup.labels, allow, warn)
    check_calibration_data(setup.cal, q, table, path, setup.robot, setup.targets, allow)
    return q, ti


@dataclass(frozen=True)
class PoseCandidates:
    """Candidate poses of a plan.

    Attributes
    ----------
    q : (N, n) controller joints [rad].
    target_index : (N,) a sensor's target per pose (None: no targets).
    table : the candidates file (None: generated).
    source : the file's name, or ``generated``.
    info : how they were generated (tried, rejected).
    """

    q: np.ndarray = field(repr=False)
    target_index: np.ndarray | None = field(repr=False)
    table: Table | None = field(repr=False)
    source: str
    info: dict[str, Any] = field(default_factory=dict)


def plan_candidates(
    setup: PlanSetup,
    *,
    path: str | None = None,
    n: int = 5000,
    ranges: np.ndarray | None = None,
    seed: int = 0,
    min_j5_deg: float = 10.0,
    min_conditioning: float = 0.05,
    floor_mm: float | None = None,
    station_mm: tuple[float, ...] | None = None,
    cone_deg: float = 30.0,
    standoff_mm: tuple[float, float] = (115.0, 135.0),
    progress: Progress | None = None,
) -> PoseCandidates:
    """The candidate poses of a plan: read from ``path`` (j1_deg..jN_deg, a sensor's
    target), or ``n`` generated within ``ranges`` (n, 2) [rad] (default the limits)
    that pass the wrist, conditioning and floor tests, face the tracker ``station_mm``
    within ``cone_deg`` (tracker) or see a target from ``standoff_mm`` (sensor).

    Returns
    -------
    PoseCandidates
        The candidate joints, their targets and where they came from.

    Raises
    ------
    DataError
        A bad candidates file, or no acceptable candidate generated.
    """
    from kinecal.planning import joint_candidates, sensor_candidates

    plan_arguments(setup, (PlanSetup, PoseCandidates), n=n, ranges=ranges)
    say, robot, inst = progress or _quiet, setup.robot, setup.instrument
    if path:
        table, _, q, ti = read_pose_file(path, robot, setup.labels)
        say("candidates", f"{q.shape[0]} poses from {path}")
        return PoseCandidates(q, ti, table, path)
    common = {
        "ranges": ranges,
        "seed": seed,
        "min_j5": np.radians(min_j5_deg),
        "min_conditioning": min_conditioning,
        "floor_z": None if floor_mm is None else floor_mm * 1e-3,
    }
    say("candidates", f"generating {n} ({inst.name})")
    if inst.name == "sensor":
        assert inst.targets is not None
        so = standoff_mm
        c = sensor_candidates(
            setup.model, setup.params, inst.targets, n,
            standoff=(so[0] * 1e-3, so[1] * 1e-3), **common,
        )  # fmt: skip
    else:
        st = station_mm
        c = joint_candidates(
            setup.model, setup.params, n,
            station=None if st is None else np.array(st) * 1e-3,
            cone=np.radians(cone_deg), **common,
        )  # fmt: skip
    if c.q_ctrl.shape[0] < 1:
        why = ", ".join(f"{v} {k}" for k, v in c.rejected.items() if v)
        raise DataError(
            f"--n-candidates {n}: no acceptable candidate among "
            f"{c.tried} poses drawn ({why}); expected looser --joint-range, "
            "--min-j5-deg, --min-conditioning, --floor-mm, --station or --cone-deg."
        )
    info = {"generated": True, "tried": c.tried, "rejected": c.rejected}
    return PoseCandidates(c.q_ctrl, c.target_index, None, "generated", info)


@dataclass(frozen=True)
class PlanRun:
    """What :func:`plan_measurements` chose.

    Attributes
    ----------
    plan : the chosen poses, their order and figures.
    rows : the chosen candidates' rows (file lines, or 1-based generated indices).
    lines : PLAN.csv's lines (the chosen rows of the candidates file, in order).
    report : report.json's content (file units: mm, deg), without its manifest.
    """

    plan: Plan = field(repr=False)
    rows: list[int]
    lines: list[str] = field(repr=False)
    report: dict[str, Any] = field(repr=False)

    def csv_text(self) -> str:
        """PLAN.csv."""
        return "\n".join(self.lines) + "\n"

    def summary(self, out: Path, rep: Path) -> dict[str, Any]:
        """The JSON object ``kinecal plan --json`` prints."""
        keys = ("n_poses", "predicted", "random", "selection", "order")
        doc = self.report
        return {k: doc[k] for k in keys} | {"out": str(out), "report": str(rep)}

    def summary_lines(
        self, out: Path, rep: Path, extra: list[str] | None = None
    ) -> list[tuple[str, bool]]:
        """The lines ``kinecal plan`` prints, each with whether it goes to stderr
        (``extra``: further files written)."""
        doc = self.report
        lines: list[tuple[str, bool]] = []

        def say(text: str, err: bool = False) -> None:
            lines.append((text, err))

        d, pr, rd = doc["design"], doc["predicted"], doc["random"]
        say(f"candidates {doc['candidates']['n']} ({doc['candidates']['source']})")
        say(
            f"model      {doc['model']}: {d['parameters']} parameters in the design"
            + (
                f"; not determined by any candidate: {', '.join(d['not_determined'])}"
                if d["not_determined"]
                else ""
            )
        )
        s = doc["selection"]
        say(
            f"plan       {doc['n_poses']} poses, {doc['criterion']}-optimal (greedy + "
            f"{doc['exchange']}: {s['swaps']} swaps, {s['seconds']:.2f} s)"
        )
        if doc.get("before"):
            b = doc["before"]
            say(
                f"before     held-out RMS {b['heldout_rms_mm']:.4f} mm = {b['ratio']:.3f}x "
                "the noise floor"
            )
        say(
            f"predicted  held-out RMS {pr['heldout_rms_mm']:.4f} mm = {pr['ratio']:.3f}x the "
            f"noise floor {pr['floor_mm']:.4f} mm"
        )
        say(
            f"random     held-out RMS {rd['heldout_rms_mm_mean']:.4f} mm = {rd['ratio']:.3f}x "
            f"(mean of {rd['draws']} random plans of {doc['n_poses']})"
        )
        ratios = [
            (p["std_planned"] / p["std_random"], p["name"])
            for p in doc["parameters"]
            if p["std_random"]
        ]
        loose = sorted(
            (
                (p["std_planned"] / p["prior_std"], p["name"])
                for p in doc["parameters"]
                if p["prior_std"]
            ),
            reverse=True,
        )[:3]
        if ratios:
            med = sorted(r for r, _ in ratios)[len(ratios) // 2]
            text = f"std        planned / random: median {med:.2f} over the parameters"
            if loose:
                text += "; least determined (std / prior): " + ", ".join(
                    f"{name} {r:.2f}" for r, name in loose
                )
            say(text)
        o = doc["order"]
        say(
            f"motion     {o['path_deg']:.0f} deg of largest-joint motion along the plan "
            f"({o['path_unordered_deg']:.0f} in the order chosen)"
        )
        for w in doc["warnings"]:
            say(f"warning    {w}", True)
        say(f"wrote      {', '.join(map(str, [out, rep, *(extra or [])]))}")
        return lines


def plan_measurements(
    setup: PlanSetup,
    candidates: PoseCandidates,
    n: int,
    *,
    criterion: str = "I",
    exchange: str = "fedorov",
    priors: str = "all",
    measured: np.ndarray | None = None,
    measured_target_index: np.ndarray | None = None,
    data_path: str | None = None,
    random_draws: int = 20,
    seed: int = 0,
    option: str = "--poses",
    progress: Progress | None = None,
) -> PlanRun:
    """Choose ``n`` of the ``candidates`` that determine ``setup``'s model best, as
    ``kinecal plan`` does: ``criterion`` I (mean prediction variance, default), D, A,
    E or G, greedy then ``exchange``; ordered for short joint motion; compared with
    ``random_draws`` random plans. A sequential plan starts from the information of
    the ``measured`` poses (its calibration's data, ``data_path``).

    Returns
    -------
    PlanRun
        The plan, PLAN.csv's lines and report.json's content.

    Raises
    ------
    DataError
        Fewer distinct candidates than ``n`` (``option``: the option that asked).
    """
    from kinecal.planning import plan_poses

    plan_arguments(setup, (PlanSetup, PoseCandidates), candidates=candidates, n=n)
    plan_arguments(setup, (PlanSetup, PoseCandidates), measured=measured)
    say = progress or _quiet
    _check_poses(setup, candidates, n, option, measured is None and setup.cal is None)
    say("plan", f"{n} of {candidates.q.shape[0]} poses, {criterion}-optimal")
    cal = setup.cal
    pl = plan_poses(
        setup.model,
        setup.params,
        candidates.q,
        n,
        setup.instrument,
        criterion=criterion,
        exchange=exchange,
        priors=priors,
        target_index=candidates.target_index,
        calibrated=cal is not None,
        measured=measured,
        measured_target_index=measured_target_index,
        calibrated_std=None if cal is None else cal.std,
        random_draws=random_draws,
        seed=seed,
    )
    if candidates.table is not None:
        t = candidates.table
        lines = [",".join(t.header)] + [",".join(t.rows[i]) for i in pl.index]
        rows = [int(t.lines[i]) for i in pl.index]
    else:
        lines = pose_lines(setup.robot, pl.q_ctrl, pl.target_index, setup.labels)
        rows = [int(i) + 1 for i in pl.index]
    settings = {"criterion": criterion, "exchange": exchange, "priors": priors}
    doc = _report(pl, setup, candidates, rows, settings, data_path)
    return PlanRun(pl, rows, lines, doc)


def _check_poses(
    setup: PlanSetup, cand: PoseCandidates, n: int, option: str, first: bool
) -> None:
    """Refuse a plan from fewer distinct candidates (copies of one pose would be chosen
    again), and a ``first`` plan (nothing measured before) whose poses give no more
    residuals than the model has parameters (no calibration would accept it)."""
    from kinecal._stats import distinct_rows

    ti = cand.target_index
    key = cand.q if ti is None else np.column_stack([cand.q, ti])
    distinct = distinct_rows(key)
    if distinct < n:
        src = cand.source
        where = (
            f"{src}: the {key.shape[0]} rows hold"
            if src != "generated"
            else f"the {key.shape[0]} generated candidates (--joint-range) hold"
        )
        raise DataError(
            f"{where} only {distinct} distinct pose{'s' if distinct != 1 else ''}, but "
            f"{option} {n} asks for {n}; expected at least {n} different candidate poses."
        )
    rows, size = (6 if setup.instrument.name == "pose" else 3), setup.model.size
    if first and n * rows <= size:
        raise DataError(
            f"{option} {n}: {n} poses give {n * rows} residuals for the "
            f"{size} parameters of the '{setup.model.spec.name}' model, too few for "
            f"any calibration; expected at least {size // rows + 1} poses (plan at "
            f"least {-(-2 * size // rows)}, several times more for a reliable result)."
        )


def _report(
    pl: Plan,
    setup: PlanSetup,
    cand: PoseCandidates,
    rows: list[int],
    settings: dict[str, str],
    data_path: str | None,
) -> dict[str, Any]:
    """The content of the plan's report.json (file units: mm, deg), without the
    manifest."""
    from kinecal._version import __version__
    from kinecal.planning import prior_sigma

    pb = pl.problem
    L = pb.model.layout
    free = np.flatnonzero(pb.free)
    ps = prior_sigma(pb.model, settings["priors"])
    params = []
    for k, i in enumerate(free):
        f = L.specs[i].unit.to_file
        params.append(
            {
                "name": L.names[i],
                "unit": L.specs[i].unit.file_unit,
                "std_planned": pl.planned.std[k] * f,
                "std_random": pl.random.std[k] * f,
                "std_before": None if pl.before is None else pl.before.std[k] * f,
                "prior_std": ps[i] * f if np.isfinite(ps[i]) else None,
            }
        )

    def pred(p: Any) -> dict[str, float]:
        return {
            "heldout_rms_mm": p.heldout_rms * 1e3,
            "model_rms_mm": p.model_rms * 1e3,
            "floor_mm": p.floor * 1e3,
            "ratio": p.ratio,
        }

    s = pl.selection
    inst = setup.instrument
    return {
        "kinecal_version": __version__,
        "robot": setup.robot.name,
        "model": pb.model.spec.name,
        "instrument": inst.name,
        **settings,
        "noise_mm": inst.noise * 1e3,
        "noise_deg": float(np.degrees(inst.noise_rot)) if inst.kind == "pose" else None,
        "n_poses": int(pl.index.size),
        "sequential": None
        if setup.cal is None
        else {"model": setup.model_name, "data": data_path},
        "candidates": {"n": int(cand.q.shape[0]), "source": cand.source, **cand.info},
        "design": {
            "parameters": pb.size,
            "not_determined": [d.name for d in pb.identifiability.dropped],
            "information": "posterior: sum_c F_c^T F_c + prior precision, F_c = whitened "
            "Jacobian with scaled columns; covariance of the MAP estimate = its inverse",
            "design_point": "calibrated parameters"
            if setup.cal is not None
            else "nominal kinematics, lambda* = 1e-4 rad/m, link moments 0.3-0.5 m",
        },
        "selection": {
            "value": s.value,
            "greedy_value": s.greedy_value,
            "swaps": s.swaps,
            "sweeps": s.sweeps,
            "seconds": s.seconds,
        },
        "predicted": {
            **pred(pl.planned),
            "formula": "sqrt(3 sigma^2 + tr(M^-1 W)), "
            "W = mean over candidates of G_c^T G_c",
        },
        "random": {
            "draws": int(pl.random.heldout_rms.size),
            "heldout_rms_mm_mean": pl.random.mean_rms * 1e3,
            "heldout_rms_mm_sd": float(np.std(pl.random.heldout_rms) * 1e3),
            "ratio": pl.random.ratio,
        },
        "before": None if pl.before is None else pred(pl.before),
        "parameters": params,
        "order": {
            "candidate_rows": rows,
            "path_deg": float(np.degrees(pl.path)),
            "path_unordered_deg": float(np.degrees(pl.path_unordered)),
        },
        "warnings": pl.warnings,
    }


def report_path(out: str, report: str | None) -> Path:
    """Where a plan's report goes: ``report``, else PLAN.report.json beside ``out``."""
    if report:
        return Path(report)
    p = Path(out)
    return p.with_name(p.stem + ".report.json")
