"""Franka FR3 with an eye-in-hand camera seeing a board (114 poses, 7 joints).

The camera's pose in the board frame is the measurement: pose data whose "user frame"
is the board and whose tool is the camera (hand-eye found by the calibration, no guess).
What it shows: a 7-joint MDH robot, camera-grade (mm) noise, cross-validated accuracy, and
the workflow for a new set-up: calibrate on some poses, then score poses taken with the
board moved elsewhere after re-registering the user frame (``evaluate --refit user``).

    python examples/franka_fr3_camera.py [--out DIR]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from _realdata import DATA, cv_table, print_table, save, to_kinecal_csv
from kinecal.geometry import euler_zyx_to_matrix
from kinecal.identification import (
    Measurements,
    calibrate,
    evaluate,
    registered_model,
)
from kinecal.io import save_model
from kinecal.robot import load_robot

SOURCE = DATA / "franka_fr3_eyeinhand_camera" / "fr3_calib_data.npz"


def load() -> Measurements:
    """joint_positions [rad], camera_poses T_board_cam [m]; tcp_poses (robot FK) unused."""
    z = np.load(SOURCE)
    T = z["camera_poses"]
    return Measurements(
        "pose",
        z["joint_positions"],
        T[:, :3, 3],
        R_user_cam=T[:, :3, :3],
        rows=np.arange(1, T.shape[0] + 1),
        source=str(SOURCE),
    )


def moved_board(meas: Measurements) -> Measurements:
    """The same poses seen from a board placed elsewhere (a new set-up): every
    measurement re-expressed in a frame turned 35 deg and shifted 0.4 m."""
    R = euler_zyx_to_matrix(np.radians([35.0, 4.0, -3.0]))
    t = np.array([0.4, -0.25, 0.05])
    return Measurements(
        "pose",
        meas.q_ctrl,
        meas.p @ R.T + t,
        R_user_cam=R @ meas.R_user_cam,
        rows=meas.rows,
        source=meas.source + " (board moved)",
    )


def main(out: Path) -> dict[str, object]:
    robot = load_robot("franka-fr3")
    meas = to_kinecal_csv(load(), robot, out / "fr3_poses.csv")
    print(
        f"{meas.n} poses of a Franka FR3 from {SOURCE.name}, written as {out / 'fr3_poses.csv'}"
    )
    rows = cv_table(robot, meas)
    print_table("Franka FR3, eye-in-hand camera, 5-fold cross-validation", rows)

    # A new set-up: calibrate on the first 70 poses, score the other 44 after the board
    # was moved, re-registering only the user frame on them.
    train, test = (
        meas.subset(np.arange(70)),
        moved_board(meas.subset(np.arange(70, meas.n))),
    )
    res = calibrate(robot, train, "full")
    save_model(out / "model.yaml", res.calibrated, force=True)
    before = evaluate(registered_model(res), test, refit_user=True).metrics
    after = evaluate(res.calibrated, test, refit_user=True).metrics
    kin = evaluate(
        calibrate(robot, train, "kinematic").calibrated, test, refit_user=True
    )
    print(
        f"new set-up (board moved), 70 poses to calibrate, {test.n} to test, user frame "
        f"refitted: nominal {before.rms_mm:.2f} mm, kinematic {kin.metrics.rms_mm:.2f} "
        f"mm, full model {after.rms_mm:.2f} mm RMS"
    )
    for line in res.warnings:
        print("  " + line)
    summary = {
        "dataset": "franka_fr3_eyeinhand_camera",
        "n": meas.n,
        "cv": rows,
        "new_setup": {
            "n_train": train.n,
            "n_test": test.n,
            "nominal_rms_mm": before.rms_mm,
            "kinematic_rms_mm": kin.metrics.rms_mm,
            "full_rms_mm": after.rms_mm,
        },
    }
    save(out, summary)
    return summary


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "out" / "fr3")
    main(ap.parse_args().out)
