"""Issue 36: the closed-form start of point data solves its linear step by the normal
equations at every size (the dense least squares of 3N rows it replaces took 3.6 ms of a
2000-pose calibration), with the same solution: at the frames' rotations it returns, the
tool point and the frame translation are the dense least-squares ones."""

from __future__ import annotations

import numpy as np

from kinecal.identification._init import _flange, _init_point
from kinecal.identification._problem import Problem


def test_the_point_closed_form_solves_no_dense_least_squares(monkeypatch):
    from kinecal.workflows._simulate import simulate_paper_experiment

    e = simulate_paper_experiment(2, n_train=300).experiment
    meas = e.train
    cm = Problem.make(e.truth.robot, meas, "kinematic").model
    x = cm.nominal.copy()
    x[cm.base_index] = 0.0
    R_fl, o_fl = _flange(cm, x, meas)

    def refused(*a, **k):
        raise AssertionError("a dense least squares in the closed form")

    with monkeypatch.context() as mp:
        mp.setattr(np.linalg, "lstsq", refused)
        R_b, t_b, tool, loose = _init_point(cm, x, meas, flange=(R_fl, o_fl))
    assert loose == [] and R_b.shape == (1, 3, 3) and tool.shape == (1, 3)
    # The dense least squares of the tool point and the translation at these rotations
    # (with the same pull towards the nominal tool point).
    _, t_cam = cm.cam_frames(x)
    reg = 1e-4 * np.sqrt(meas.n)
    A = np.concatenate(
        [
            np.einsum("ij,njk->nik", R_b[0], R_fl),
            np.broadcast_to(np.eye(3), (meas.n, 3, 3)),
        ],
        axis=2,
    ).reshape(-1, 6)
    b = (meas.p - o_fl @ R_b[0].T).reshape(-1)
    A2 = np.concatenate([A, reg * np.eye(3, 6)])
    b2 = np.concatenate([b, reg * t_cam[0]])
    sol = np.linalg.lstsq(A2, b2, rcond=None)[0]
    np.testing.assert_allclose(tool[0], sol[:3], rtol=0, atol=1e-9)
    np.testing.assert_allclose(t_b[0], sol[3:], rtol=0, atol=1e-9)
    # ... and the points' true frame (sub-millimetre noise, nominal kinematics).
    assert np.linalg.norm(A @ sol - b) / np.sqrt(meas.n) < 5e-3
