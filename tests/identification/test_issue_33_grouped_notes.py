"""Issue 33: the unidentifiable parameters that the model's construction makes so (a
constant transmission term, d on parallel axes, a joint without gravity torque, the
general link model's body terms) are grouped in a few notes; a finding about the poses
keeps a line of its own."""

from __future__ import annotations

import numpy as np

from kinecal.identification import calibrate
from kinecal.identification._identifiability import DroppedParameter, grouped_dropped
from kinecal.robot import robot_from_urdf
from kinecal.simulation import robot_experiment, robot_truth
from tests.independent_arm import ARM7, urdf_text


def _d(name, *partners):
    return DroppedParameter(name, 1e-8, list(partners))


def test_grouped_notes_keep_real_findings():
    dropped = [
        _d("joint3.d", ("joint2.d", 1.0)),
        _d("joint1.lambda"),
        _d("joint1.k0", ("base.r", 0.1), ("base.w", 1e-3)),
        _d("joint2.ka1", ("link2.m", 2e3)),
        _d("link2.mx", ("link2.m", 0.2)),
        _d("link2.mz"),
        # Findings about the poses: each on a line of its own.
        _d("joint4.theta_offset", ("joint5.theta_offset", 0.7), ("cam.r", 0.3)),
        _d("cam.w", ("base.w", 1.0)),
        _d("joint5.d", ("joint2.d", 0.5)),  # not +-1: not the parallel-axes case
        _d("joint2.lambda", ("joint3.lambda", 0.9)),
        _d("joint3.ka2", ("joint3.theta_offset", 0.4)),
    ]
    lines = grouped_dropped(dropped)
    assert len(lines) == 2 + 5
    head, links = lines[:2]
    assert head.startswith("not identifiable by construction")
    for name in ("joint3.d", "joint1.lambda", "joint1.k0", "joint2.ka1"):
        assert name in head
    assert links.startswith("link model: 2 body terms") and "link2.mz" in links
    real = lines[2:]
    for line, d in zip(real, dropped[6:]):
        assert line == f"unidentifiable: {d.describe()}"
    assert grouped_dropped(dropped[6:]) == real
    assert grouped_dropped([]) == []


def test_seven_axis_arm_notes(tmp_path):
    """A 7-axis arm with the general link model: ~20 unidentifiable parameters, a few
    lines, every name still in them."""
    path = tmp_path / "arm7.urdf"
    path.write_text(urdf_text(ARM7, "arm7"))
    robot = robot_from_urdf(path, tip="flange")
    truth = robot_truth(robot, seed=1)
    exp = robot_experiment(truth, 1, n_train=80, n_test=1)
    ident = calibrate(robot, exp.train, "full").identifiability
    assert len(ident.dropped) >= 15
    notes = [ln for ln in ident.summary()[1:] if not ln.startswith("poorly")]
    assert len(notes) <= 3, notes
    text = "\n".join(notes)
    assert all(d.name in text for d in ident.dropped)
    assert np.sum(ident.free) == ident.rank
