"""A SCARA (all joint axes parallel: two arms and a quill, numbers made up) measured by a
laser tracker: no pose can tell the tool offset along the axes from the user frame. The
warning said "too little variation of the tool orientation ... Measure with varied
orientations", which no SCARA (nor a gantry with one rotary axis) can do; it names the
parallel axes and a measured tool length instead. An arm with crossed axes keeps the
advice to vary orientations."""

from __future__ import annotations

import numpy as np

from kinecal.identification import calibrate
from kinecal.robot import load_robot, robot_from_dict
from kinecal.simulation import robot_experiment, robot_truth

_SCARA = {
    "name": "scara",
    "convention": "dh",
    "units": {"length": "mm", "angle": "deg"},
    "joints": [
        {"theta_offset": 0, "d": 400, "a": 300, "alpha": 0, "limits": [-140, 140]},
        {"theta_offset": 0, "d": 0, "a": 250, "alpha": 180, "limits": [-140, 140]},
        {"theta_offset": 0, "d": 0, "a": 0, "alpha": 0, "limits": [0, 200],
         "type": "prismatic"},
        {"theta_offset": 0, "d": 100, "a": 0, "alpha": 0, "limits": [-300, 300]},
    ],
    "tool": {"x": 30, "y": 0, "z": 50, "r": 0, "w": 0, "p": 0},
}  # fmt: skip


def test_zoo9_scara_frames_warning_names_the_parallel_axes():
    robot = robot_from_dict(_SCARA)
    e = robot_experiment(robot_truth(robot, seed=1), seed=1, n_train=40, n_test=1)
    res = calibrate(robot, e.train, "kinematic")
    (lost,) = res.diagnostics_with("frames_undetermined")
    assert "about parallel axes only" in lost.message
    assert "measured tool length" in lost.message
    assert "Measure with varied orientations" not in lost.message
    assert np.isfinite(res.metrics_after.rms_mm)


_GANTRY = {
    "name": "gantry",
    "convention": "dh",
    "units": {"length": "mm", "angle": "deg"},
    "joints": [
        {"theta_offset": -90, "d": 0, "a": 0, "alpha": -90, "limits": [0, 2000],
         "type": "prismatic"},
        {"theta_offset": -90, "d": 0, "a": 0, "alpha": -90, "limits": [0, 1500],
         "type": "prismatic"},
        {"theta_offset": 0, "d": 0, "a": 0, "alpha": 0, "limits": [0, 800],
         "type": "prismatic"},
        {"theta_offset": 0, "d": 200, "a": 0, "alpha": 0, "limits": [-170, 170]},
    ],
}  # fmt: skip


def test_zoo9_crossed_axes_keep_the_advice_to_vary_orientations():
    from kinecal.identification._stages import _what_to_measure

    # three crossed slides and one rotary axis: the tool turns about one axis only
    assert "measured tool length" in _what_to_measure(robot_from_dict(_GANTRY))
    assert _what_to_measure(load_robot("fanuc-lrmate200id")) == (
        "Measure with varied orientations."
    )
