"""Generated candidates: even spread, no singular poses, visible to the instrument."""

from __future__ import annotations

import numpy as np
import pytest

from kinecal.models import ModelInputs
from kinecal.planning import (
    Instrument,
    halton,
    joint_candidates,
    planning_model,
    sensor_candidates,
)
from kinecal.robot import load_robot

ROBOT = load_robot("fanuc-lrmate200id")


def test_halton_points_fill_the_cube_evenly(rng):
    u = halton(1000, 6, rng)
    assert u.shape == (1000, 6) and u.min() >= 0 and u.max() < 1
    for d in range(6):
        counts = np.histogram(u[:, d], bins=10, range=(0, 1))[0]
        assert np.all(np.abs(counts - 100) <= 4), (d, counts)  # random: +-30
    # pairs of dimensions too (a 5 x 5 grid)
    h2 = np.histogram2d(u[:, 0], u[:, 1], bins=5, range=[[0, 1], [0, 1]])[0]
    assert np.all(np.abs(h2 - 40) <= 4)
    with pytest.raises(ValueError, match="dim must be between 1 and 12"):
        halton(10, 13, rng)


def test_joint_candidates_respect_ranges_wrist_and_conditioning():
    cm, x = planning_model(ROBOT, "full", Instrument())
    ranges = ROBOT.limits.copy()
    ranges[0] = np.radians([-60, 60])
    ranges[2] = np.radians([-20, 90])
    c = joint_candidates(cm, x, 800, ranges=ranges, seed=3, min_j5=np.radians(15))
    q = c.q_ctrl
    assert q.shape == (800, 6)
    assert np.all(q >= ranges[:, 0]) and np.all(q <= ranges[:, 1])
    assert np.all(np.abs(q[:, 4]) >= np.radians(15))
    J = cm.joint_jacobian(x, ModelInputs.make(q))
    J[:, :3] /= 0.415  # half the LR Mate's summed DH lengths [m]
    s = np.linalg.svd(J, compute_uv=False)
    assert np.all(s[:, -1] >= 0.05 * s[:, 0])
    assert c.rejected["near a singularity"] > 0
    assert c.rejected["wrist singularity (|J5| small)"] > 0
    assert c.tried >= 800 + sum(c.rejected.values())
    with pytest.raises(ValueError, match="lies outside its limits"):
        bad = ROBOT.limits.copy()
        bad[1] = np.radians([150, 160])
        joint_candidates(cm, x, 10, ranges=bad)


def test_tracker_line_of_sight_and_floor():
    cm, x = planning_model(ROBOT, "full", Instrument())
    station = np.array([2.0, 0.5, 0.3])
    c = joint_candidates(
        cm, x, 200, station=station, cone=np.radians(40), floor_z=-0.2, seed=1
    )
    assert c.q_ctrl.shape[0] == 200
    out = cm.evaluate(x, ModelInputs.make(c.q_ctrl), orientation=True)
    u = station - out.p_user
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    cos = np.einsum("ni,ni->n", out.R_user_cam[:, :, 2], u)
    assert np.all(cos >= np.cos(np.radians(40)) - 1e-12)
    assert np.all(ROBOT.fk_flange(c.q_ctrl)[:, 2, 3] >= -0.2 - 1e-12)  # tool = flange
    assert c.rejected["reflector not facing the station"] > 0


def test_sensor_candidates_view_the_targets_from_the_working_distance():
    targets = np.array([[0.5, 0.15, -0.25], [0.5, -0.15, -0.25], [0.4, 0.0, -0.3]])
    inst = Instrument("sensor", 5e-6, targets=targets)
    cm, x = planning_model(ROBOT, "full", inst)
    c = sensor_candidates(cm, x, targets, 90, seed=2)
    assert c.target_index is not None and c.q_ctrl.shape[0] > 45
    assert set(np.unique(c.target_index)) == {0, 1, 2}
    out = cm.evaluate(x, ModelInputs.make(c.q_ctrl), orientation=True)
    d_cam = np.einsum(
        "nji,nj->ni", out.R_user_cam, targets[c.target_index] - out.p_user
    )
    assert np.all((d_cam[:, 2] > 0.115 - 1e-4) & (d_cam[:, 2] < 0.135 + 1e-4))
    assert np.all(np.hypot(d_cam[:, 0], d_cam[:, 1]) < 1e-4)  # on the optical axis
    assert np.all(np.abs(c.q_ctrl[:, 4]) >= np.radians(10))


def test_joints_without_limits_are_planned_over_one_turn():
    """A URDF's continuous joints (Kinova Gen3: J1, J3, J5, J7) have no limits: their
    candidates spread over one turn. Before, the infinite limits gave NaN joint values
    and ``kinecal plan --robot`` an internal error (SVD did not converge)."""
    import warnings
    from pathlib import Path

    urdf = (
        Path(__file__).resolve().parents[1] / "data/vendor_urdf/kinova_gen3_7dof.urdf"
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # its base moved onto the first axis
        robot = load_robot(str(urdf))
    free = ~np.isfinite(robot.limits).all(axis=1)
    assert free.tolist() == [True, False, True, False, True, False, True]
    cm, x = planning_model(robot, "kinematic", Instrument())
    q = joint_candidates(cm, x, 300, seed=1).q_ctrl
    assert q.shape == (300, 7) and np.isfinite(q).all()
    assert np.all(np.abs(q[:, free]) <= np.pi)
    assert np.all(np.ptp(q[:, free], axis=0) > np.radians(300))  # around the turn
    lim = robot.limits[~free]
    assert np.all((q[:, ~free] >= lim[:, 0]) & (q[:, ~free] <= lim[:, 1]))
