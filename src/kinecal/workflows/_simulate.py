"""The simulation workflows of ``kinecal simulate``: one of the paper's experiments on
the LR Mate 200iD twin, or a laser-tracker calibration of a twin of any robot; and the
files they are written to (measurements, targets, the truth as a model file)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from kinecal.errors import DataError
from kinecal.robot import RobotDescription
from kinecal.simulation import Experiment

__all__ = [
    "SimulatedData",
    "simulate_paper_experiment",
    "simulate_robot_twin",
    "write_simulation",
]


@dataclass(frozen=True)
class SimulatedData:
    """What a simulation workflow made.

    Attributes
    ----------
    experiment : the truth, the data to calibrate (``train``) and to test, the targets.
    description : the true robot in words (a twin of a robot only).
    """

    experiment: Experiment
    description: str | None = None

    @property
    def robot(self) -> RobotDescription:
        """The robot as a user would describe it (the nominal one)."""
        return self.experiment.truth.robot


def simulate_paper_experiment(
    number: int = 2,
    *,
    seed: int = 0,
    n_train: int = 100,
    extras: tuple[str, ...] = (),
    noise_um: float | None = None,
    outliers: float = 0.0,
) -> SimulatedData:
    """One of the paper's experiments on the LR Mate 200iD twin, as ``kinecal simulate
    --experiment N`` makes it: 1 a 3D sensor and four ceramic spheres, 2 a laser
    tracker grid; ``extras`` effects outside every model (harmonics, wrist, masses,
    thermal),
    ``noise_um`` the per-axis noise (default: tracker 5 um + 2 um/m; sensor 4/8 um),
    ``outliers`` a fraction of tracker rows with gross errors.

    Returns
    -------
    SimulatedData
        The truth, the measurements to calibrate and to test, the targets.

    Raises
    ------
    ValueError
        ``n_train`` leaves no pose to test.
    """
    from kinecal.simulation import LaserTracker, SphereSensor, experiment1, experiment2

    if number == 2:
        tracker = (
            LaserTracker(noise_um * 1e-6, 0.0)
            if noise_um is not None
            else LaserTracker(5e-6, 2e-6)
        )
        exp = experiment2(
            seed,
            n_train=n_train,
            extras=extras,
            tracker=tracker,
            outlier_fraction=outliers,
        )
        return SimulatedData(exp)
    sensor = (
        SphereSensor(noise_um * 1e-6, 2 * noise_um * 1e-6)
        if noise_um is not None
        else None
    )
    return SimulatedData(
        experiment1(seed, n_train=n_train, extras=extras, sensor=sensor)
    )


def simulate_robot_twin(
    robot: RobotDescription,
    *,
    seed: int = 0,
    n_train: int = 100,
    n_test: int = 300,
    q_train: np.ndarray | None = None,
    extras: tuple[str, ...] = (),
    noise_um: float | None = None,
    new_session: bool = False,
    sensor: bool = False,
) -> SimulatedData:
    """A laser-tracker calibration of a twin of ``robot`` (random tolerances, gravity
    compliance from its self-weight layout or link masses), as ``kinecal simulate
    --robot`` makes it: ``n_train`` random poses (or ``q_train`` (N, n) [rad]) to
    calibrate, ``n_test`` to test, from a second tracker station with ``new_session``.
    ``sensor``: a 3D sensor on the flange and four spheres instead (``--sensor``,
    :func:`kinecal.simulation.robot_sensor_experiment`; ``noise_um`` across the optical
    axis, twice that along it).

    Returns
    -------
    SimulatedData
        The truth, the measurements to calibrate and to test (and the targets).
    """
    from kinecal.simulation import EXTRAS, LaserTracker, robot_experiment, robot_truth
    from kinecal.workflows._args import (
        count,
        joints_within_limits,
        need_robot,
        words,
    )

    need_robot(robot)
    extras = words(extras, EXTRAS, "extras")
    if q_train is not None:
        q_train = joints_within_limits(q_train, robot, "q_train")
    else:
        count(n_train, "n_train")
    _check_twin_size(
        robot, n_train if q_train is None else len(q_train), count(n_test, "n_test")
    )
    if sensor:
        from kinecal.simulation import robot_sensor_twin

        exp = robot_sensor_twin(
            robot,
            seed,
            n_train=n_train,
            n_test=n_test,
            extras=extras,
            noise_um=noise_um,
        )
        return SimulatedData(exp, exp.truth.description)
    tracker = (
        LaserTracker(noise_um * 1e-6, 0.0) if noise_um is not None else LaserTracker()
    )
    truth = robot_truth(robot, seed=seed, extras=extras)
    exp = robot_experiment(
        truth,
        seed,
        n_train=n_train,
        n_test=n_test,
        q_train=q_train,
        tracker=tracker,
        new_session=new_session,
    )
    return SimulatedData(exp, truth.description)


MAX_TWIN_POSES = 1_000_000  # --n-train + --n-test: far beyond any measured session


def _check_twin_size(robot: RobotDescription, n_train: int, n_test: int) -> None:
    """Refuse sizes no session has (10^8 poses ran out of memory and were killed) and a
    payload beyond the robot's bound before simulating (it was refused only when
    truth.yaml, an output, was written, naming that file)."""
    from kinecal.io._model_bounds import check_payload

    if n_train + n_test > MAX_TWIN_POSES:
        raise DataError(
            f"--n-train {n_train} and --n-test {n_test}: {n_train + n_test} poses; "
            f"expected at most {MAX_TWIN_POSES} in all (a tracker session has hundreds)."
        )
    if robot.payload_kg is not None:
        check_payload(robot.payload_kg, robot, "--payload-kg")


def write_simulation(
    sim: SimulatedData,
    out: Path,
    final: Path,
    robot_file: RobotDescription | None = None,
    plan: str | None = None,
) -> dict[str, str]:
    """Write the simulation's files into ``out`` (the staged folder): train.csv,
    test.csv, targets.csv (when there are targets), truth.yaml and, with a
    ``robot_file`` (the robot simulated), robot.yaml; return them by role, named as
    they will be in ``final`` (the --out folder). ``plan``: the pose file whose rows
    train.csv measures (``--plan``); its ISO 9283 columns
    (:data:`kinecal.workflows._iso9283.PLAN_COLUMNS`) are kept in train.csv."""
    from kinecal.demo import truth_model
    from kinecal.io import (
        atomic_write_text,
        measurements_to_csv,
        save_model,
        write_measurements,
        write_targets,
    )

    exp = sim.experiment
    robot = exp.truth.robot
    names = {"train": "train.csv", "test": "test.csv", "truth": "truth.yaml"}
    # force: prepare_output_dir has checked the folder (the --force of the command)
    train = measurements_to_csv(exp.train, robot)
    text = _with_plan_columns(train, plan) if plan is not None else train
    atomic_write_text(out / "train.csv", text, force=True)
    write_measurements(out / "test.csv", exp.test, robot, force=True)
    if exp.targets is not None:
        labels, p, r = exp.targets
        write_targets(out / "targets.csv", labels, p, r, force=True)
        names["targets"] = "targets.csv"
    save_model(out / "truth.yaml", truth_model(exp), force=True)
    if robot_file is not None:
        from kinecal import _yaml as yaml
        from kinecal.robot import dump_robot

        rf = robot_file
        header = f"# {rf.name} as simulated by kinecal simulate ({rf.source}).\n"
        text = header + yaml.dump(dump_robot(rf), sort_keys=False)
        atomic_write_text(out / "robot.yaml", text, force=True)
        names["robot"] = "robot.yaml"
    return {k: str(final / v) for k, v in names.items()}


def _with_plan_columns(train: str, plan: str) -> str:
    """train.csv's text with the plan's ISO 9283 columns (an ISO test program's point
    and cycle, its command pose) added after its own, so that the simulated test runs
    through ``evaluate --iso9283`` as a measured one would (the rows are the plan's, in
    its order)."""
    import csv
    import io

    from kinecal.io import read_table
    from kinecal.workflows._iso9283 import PLAN_COLUMNS

    t = read_table(plan)
    keep = [c for c in t.header if c.strip().lower() in PLAN_COLUMNS]
    lines = train.splitlines()
    if not keep:
        return train
    if len(lines) != len(t) + 1:  # one measured row per plan row
        raise DataError(
            f"{plan}: {len(t)} rows, but the simulation measured {len(lines) - 1}."
        )
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(keep)
    w.writerows(zip(*(t.column(c) for c in keep)))
    extra = buf.getvalue().splitlines()
    return "".join(f"{a},{b}\n" for a, b in zip(lines, extra))
