"""UR10e with 6-D motion-capture poses (FIGAROH example data, 23 poses).

What it shows: reading a foreign file (metres, radians, roll-pitch-yaw), converting it to a
kinecal measurement CSV, the cross-validated accuracy of the nominal kinematics and of
kinecal's models on real, mm-noisy data with very few poses, and how kinecal tells that
a nominal table is wrong. The data set calls the robot a UR10, but it is an e-Series
UR10e: on the UR10e's own table the nominal robot with fitted frames leaves 4 mm, on the
CB-series UR10 table 12 mm, and the check of a UR10 calibration against a fit without
priors says so (``nominal_check``).

    python examples/ur10_mocap.py [--out DIR]
"""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path

import numpy as np

from _realdata import DATA, cv_table, print_table, save, to_kinecal_csv
from kinecal.geometry import rpy_to_matrix
from kinecal.identification import Measurements, calibrate, nominal_check
from kinecal.io import save_model
from kinecal.robot import load_robot

SOURCE = DATA / "ur10_figaroh_mocap" / "calibration.csv"


def load() -> Measurements:
    """x1, y1, z1 [m], phix1..phiz1 [rad, pinocchio rpy: Rz Ry Rx], six joints [rad]."""
    d = np.loadtxt(SOURCE, delimiter=",", skiprows=1)
    return Measurements(
        "pose",
        d[:, 6:12],
        d[:, :3],
        R_user_cam=rpy_to_matrix(d[:, 3:6]),
        rows=np.arange(2, d.shape[0] + 2),
        source=str(SOURCE),
    )


def wrong_nominal(meas: Measurements) -> list[str]:
    """What kinecal says when the same poses are calibrated on the CB-series UR10 table."""
    cb = load_robot("ur10")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the findings are returned, not warned
        res = calibrate(cb, meas, "kinematic")
    return [d.message for d in nominal_check(res, cb, meas)]


def main(out: Path) -> dict[str, object]:
    robot = load_robot("ur10e")
    meas = to_kinecal_csv(load(), robot, out / "ur10_poses.csv")
    print(
        f"{meas.n} poses of a UR10e from {SOURCE.name}, written as "
        f"{out / 'ur10_poses.csv'}"
    )
    rows = cv_table(robot, meas, leave_one_out=("nominal (frames only)", "kinematic"))
    print_table("UR10e, motion capture, 5-fold cross-validation", rows)
    res = calibrate(robot, meas, "kinematic")
    save_model(out / "model.yaml", res.calibrated, force=True)
    print(
        f"all {meas.n} poses, kinematic model: RMS {res.metrics_before.rms_mm:.2f} mm "
        f"before, {res.metrics_after.rms_mm:.2f} mm after; model: {out / 'model.yaml'}"
    )
    for line in res.identifiability.summary()[:1] + res.warnings:
        print("  " + line)
    found = nominal_check(res, robot, meas)
    cb = wrong_nominal(meas)
    print("the same poses on the CB-series UR10 table:")
    for line in cb:
        print("  " + line)
    summary = {
        "dataset": "ur10_figaroh_mocap",
        "robot": robot.name,
        "n": meas.n,
        "cv": rows,
        "fit_all": {
            "before_rms_mm": res.metrics_before.rms_mm,
            "after_rms_mm": res.metrics_after.rms_mm,
            "warnings": res.warnings,
            "nominal_check": [d.code for d in found],
        },
        "cb_table_check": cb,
    }
    save(out, summary)
    return summary


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "out" / "ur10")
    main(ap.parse_args().out)
