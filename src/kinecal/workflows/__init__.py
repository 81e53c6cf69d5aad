"""Typed workflows: what a ``kinecal`` command does, as one function a Python user can call.

The command line parses options, checks its arguments, calls the workflow and writes and
prints its result; the workflow does the work and returns a frozen result.

>>> from kinecal.io import read_measurements                     # doctest: +SKIP
>>> from kinecal.robot import load_robot
>>> from kinecal.workflows import calibrate_measurements
>>> robot = load_robot("fanuc-lrmate200id")
>>> run = calibrate_measurements(robot, read_measurements("train.csv", robot), cv_folds=5)
>>> run.spec.name, run.held_out.transfer.model.rms_mm
"""

from __future__ import annotations

from kinecal.workflows._calibrate import CalibrationRun, calibrate_measurements

__all__ = ["CalibrationRun", "calibrate_measurements"]
