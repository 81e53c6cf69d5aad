"""Closed-form starting values of the user and cam frames from nominal kinematics.

No user guess is needed (DESIGN §5):

* point data: Kabsch between nominal tool points and measurements, alternating with a
  linear least-squares solve for the tool point (per marker) and the frame translations;
* pose data: ``M_i = Y F_i X`` solved as AX = YB (Shah's Kronecker method);
* sensor data: a linear hand-eye solve ``F_i X p_cam,i = b_k`` for the cam frame and the
  targets in the base frame, then Kabsch from the base to the user frame.

Frames whose Euler pitch ``|w|`` comes within 15 deg of 90 deg get a reference rotation so
the identification never works at gimbal lock.
"""

from __future__ import annotations

import numpy as np

from kinecal._stats import present
from kinecal.errors import DataError, IdentifiabilityError
from kinecal.geometry import (
    make_transform,
    matrix_to_euler_zyx,
    project_to_so3,
    rigid_fit_nearest,
    solve_axyb,
    transform_inv,
)
from kinecal.measurement import _blocks
from kinecal.measurement._measurements import Measurements
from kinecal.models import CalibrationModel
from kinecal.typing import Float

__all__ = ["closed_form_frames", "euler_with_reference", "initial_frames"]

Flange = tuple[Float, Float]  # flange frames (R (N, 3, 3), o (N, 3)) in the model base

_GIMBAL_MARGIN = np.radians(15.0)


def _flange(
    model: CalibrationModel, params: Float, meas: Measurements
) -> tuple[Float, Float]:
    """Flange frames ``(R (N, 3, 3), o (N, 3))``.

    Large data by blocks of poses, from the model's own evaluation of the tool pose with
    the user frame at the identity (the compiled kernel where it is built; the same
    numbers to rounding): ``R_fl = R_user_cam R_fc^T``, ``o_fl = p - R_fl (t_fc + R_fc
    p_cam)``."""
    inputs = meas.model_inputs()
    if 3 * meas.n <= _blocks.BLOCK_ROWS:
        return model.flange_frames(params, inputs)
    bare = model.with_references(np.broadcast_to(np.eye(3), model.R_ref_base.shape))
    x = params.copy()
    x[bare.base_index] = 0.0
    R_fc, t_fc = bare.cam_frames(x)
    R = np.empty((meas.n, 3, 3))
    o = np.empty((meas.n, 3))
    for rows, inp in _blocks.block_inputs(inputs, _blocks.BLOCK_ROWS // 3):
        out = bare.evaluate(x, inp, orientation=True)
        assert out.R_user_cam is not None
        mi = inp.marker_index
        R_fl = out.R_user_cam @ np.swapaxes(R_fc, 1, 2)[mi]
        fl_p = t_fc[mi] + np.einsum("nij,nj->ni", R_fc[mi], inp.p_cam)
        R[rows] = R_fl
        o[rows] = out.p_user - np.einsum("nij,nj->ni", R_fl, fl_p)
        _blocks.tick(rows.stop, meas.n)
    return R, o


def _init_point(
    model: CalibrationModel,
    params: Float,
    meas: Measurements,
    n_iter: int = 50,
    flange: Flange | None = None,
) -> tuple[Float, Float, Float, list[int]]:
    """Base rotations (S, 3, 3), base translations (S, 3), tool points (M, 3), and the
    sets whose points do not fix their rotation: Kabsch per set, alternating with the
    linear least squares of the tool points and the frame translations, by its normal
    equations in each set's rotated frame (any size of data; the dense solve it replaces
    took 3.6 ms of a 2000-pose calibration's 64, the same numbers to 1e-15).

    Row i, ``R_b[s] (R_fl,i tool[m] + o_fl,i) + t_b[s] = p_i``, turned by ``R_b[s]ᵀ``
    (which keeps the squared error) reads ``R_fl,i tool[m] + t'_s = R_b[s]ᵀ p_i - o_fl,i``
    with ``t'_s = R_b[s]ᵀ t_b[s]``: its normal matrix depends on the flange frames only
    and is formed once; each round is then a few matrix-vector products over the poses.
    A tiny pull of the tool points towards their nominal values (weight ``reg``, its
    bias about ``reg^2 / sigma_min^2``, negligible whenever the tool point is
    identifiable): without it a design with one tool orientation (tool point and user
    origin then trade off exactly) gives a minimum-norm solution kilometres away.
    """
    R_fl, o_fl = flange or _flange(model, params, meas)
    S, M = len(model.spec.sets), len(model.spec.markers)
    _, t_cam = model.cam_frames(params)
    tool, tool_nominal = t_cam.copy(), t_cam.copy()
    reg = 1e-4 * np.sqrt(meas.n)
    R_b = np.broadcast_to(np.eye(3), (S, 3, 3)).copy()
    t_b = np.zeros((S, 3))
    si, mi, p = meas.set_index, meas.marker_index, meas.p
    sets, marks = _groups(si, S), _groups(mi, M)  # (views where one group has all)
    for s, rows in enumerate(sets):
        if np.sum(si[rows] == s) < 3:
            raise IdentifiabilityError(
                f"{meas.source}: {_set_name(model.spec.sets[s])} has "
                f"{_rows(int(np.sum(si[rows] == s)))}; a user frame needs at least 3."
            )
    # Normal matrix of the unknowns (tool points, then t'_s): constant.
    n_x = 3 * M + 3 * S
    K = np.zeros((n_x, n_x))
    Xs = [R_fl[rows].reshape(-1, 3) for rows in marks]  # (3 n_m, 3)
    for m in range(M):
        tm = slice(3 * m, 3 * m + 3)
        K[tm, tm] = Xs[m].T @ Xs[m] + reg**2 * np.eye(3)
        for s in range(S):
            cell = slice(None) if S == M == 1 else (mi == m) & (si == s)
            C = R_fl[cell].sum(axis=0).T  # sum of R_fl,i^T
            ts = slice(3 * M + 3 * s, 3 * M + 3 * s + 3)
            K[tm, ts], K[ts, tm] = C, C.T
    for s, rows in enumerate(sets):
        ts = slice(3 * M + 3 * s, 3 * M + 3 * s + 3)
        K[ts, ts] = np.sum(si[rows] == s) * np.eye(3)

    def turned(v: Float) -> Float:  # (N, 3): R_fl,i v[m_i]
        out = np.empty((meas.n, 3))
        for m, rows in enumerate(marks):
            out[rows] = (Xs[m] @ v[m]).reshape(-1, 3)
        return out

    prev = np.inf
    loose: set[int] = set()
    b = np.empty((meas.n, 3))
    for k in range(n_iter):
        p_base = o_fl + turned(tool)
        for s, rows in enumerate(sets):
            R_b[s], t_b[s], determined = rigid_fit_nearest(
                p_base[rows], p[rows], R_b[s]
            )
            if not determined:
                loose.add(s)
            b[rows] = p[rows] @ R_b[s] - o_fl[rows]  # R_b^T p - o_fl
        h = np.zeros(n_x)
        for m, rows in enumerate(marks):
            h[3 * m : 3 * m + 3] = Xs[m].T @ b[rows].reshape(-1)
            h[3 * m : 3 * m + 3] += reg**2 * tool_nominal[m]
        for s, rows in enumerate(sets):
            h[3 * M + 3 * s : 3 * M + 3 * s + 3] = b[rows].sum(axis=0)
        _blocks.beat(f"closed form, round {k + 1}")
        sol = np.asarray(np.linalg.solve(K, h), np.float64)
        tool = sol[: 3 * M].reshape(M, 3)
        t_rot = sol[3 * M :].reshape(S, 3)
        t_b = np.einsum("sij,sj->si", R_b, t_rot)
        res = float(np.linalg.norm(turned(tool) + t_rot[si] - b))
        if abs(prev - res) <= 1e-12 * max(res, 1e-9):
            break
        prev = res
    return R_b, t_b, tool, sorted(loose)


def _groups(index: np.ndarray, count: int) -> list[np.ndarray | slice]:
    """The rows of each group: all (a slice, no copy) when there is one group."""
    if count == 1:
        return [slice(None)]
    return [np.flatnonzero(index == k) for k in range(count)]


def _init_pose(
    model: CalibrationModel, params: Float, meas: Measurements, flange: Flange | None
) -> tuple[Float, Float, Float, Float]:
    """Base (S) and cam (M) frames from AX = YB."""
    assert meas.R_user_cam is not None
    R_fl, o_fl = flange or _flange(model, params, meas)
    F = make_transform(R_fl, o_fl)
    Mm = make_transform(meas.R_user_cam, meas.p)
    S, Mk = len(model.spec.sets), len(model.spec.markers)
    si, mi = meas.set_index, meas.marker_index
    # The most frequent marker fixes Y per set; then every marker's X given Y.
    m0 = int(np.bincount(mi, minlength=Mk).argmax())
    Y = np.zeros((S, 4, 4))
    X = np.zeros((Mk, 4, 4))
    for s in range(S):
        rows = (si == s) & (mi == m0)
        if rows.sum() < 3:
            rows = si == s
        # M_i = Y F_i X  <=>  M_i X^-1 = Y F_i : AX' = YB with A = M, B = F, X' = X^-1.
        try:
            Xinv, Ys = solve_axyb(Mm[rows], F[rows])
        except ValueError:  # fewer than 3 poses, or rotations about one axis at most
            raise DataError(_one_axis(meas, model.spec.sets[s], S > 1)) from None
        Y[s] = Ys
        if s == 0:
            X[m0] = transform_inv(Xinv)
    for m in range(Mk):
        rows = mi == m
        Xi = np.einsum("nij,njk->nik", transform_inv(Y[si[rows]] @ F[rows]), Mm[rows])
        X[m] = make_transform(
            project_to_so3(Xi[:, :3, :3].mean(axis=0)), Xi[:, :3, 3].mean(axis=0)
        )
    return Y[:, :3, :3], Y[:, :3, 3], X[:, :3, :3], X[:, :3, 3]


def _one_axis(meas: Measurements, label: str, several: bool) -> str:
    """The message for pose data whose orientations cannot fix the tool and user frames."""
    where = f" (set {label})" if several else ""
    return (
        f"{meas.source}{where}: the measured tool orientations turn about one axis at "
        "most (or there are fewer than 3 poses), so they cannot determine the tool's "
        "and the user frame's rotation; expected poses that turn the tool about at "
        "least two different axes, or position-only data (without the orientation "
        "columns)."
    )


def _init_sensor(
    model: CalibrationModel, params: Float, meas: Measurements, flange: Flange | None
) -> tuple[Float, Float, Float, Float, list[int]]:
    """Cam frames (M) by a linear hand-eye solve, then user frames (S) by Kabsch; the
    sets whose targets do not fix their rotation."""
    assert meas.targets is not None and meas.target_index is not None
    R_fl, o_fl = flange or _flange(model, params, meas)
    S, Mk = len(model.spec.sets), len(model.spec.markers)
    K = meas.targets.shape[0]
    si, mi, ti = meas.set_index, meas.marker_index, meas.target_index
    N = meas.n
    pc = meas.p
    # Unknowns: per marker M (9, row-major, a relaxed rotation) and t (3); per
    # (set, target) the target in the base frame b (3).
    n_x = 12 * Mk
    key = si * K + ti
    n_b = 3 * S * K
    A = np.zeros((N, 3, n_x + n_b))
    # R_F M p = sum_ab R_F[:, a] p[b] M[a, b]: coefficients of M in row-major order.
    kron = np.einsum("nj,nik->nikj", pc, R_fl).reshape(N, 3, 9)
    for m in range(Mk):
        rows = mi == m
        A[rows, :, 12 * m : 12 * m + 9] = kron[rows]
        A[rows, :, 12 * m + 9 : 12 * m + 12] = R_fl[rows]
    for k in present(key):
        rows = key == k
        A[rows, :, n_x + 3 * k : n_x + 3 * k + 3] = -np.eye(3)
    b = -o_fl
    used = np.concatenate([np.ones(n_x, bool), np.zeros(n_b, bool)])
    for k in present(key):
        used[n_x + 3 * k : n_x + 3 * k + 3] = True
    Au = A.reshape(3 * N, -1)[:, used]
    sol_u, *_ = np.linalg.lstsq(Au, b.reshape(-1), rcond=None)
    sol = np.zeros(n_x + n_b)
    sol[used] = sol_u
    R_c = np.zeros((Mk, 3, 3))
    for m in range(Mk):
        R_c[m] = project_to_so3(sol[12 * m : 12 * m + 9].reshape(3, 3))
    # Re-solve the translations with the rotations fixed.
    rhs = -o_fl - np.einsum("nij,nj->ni", R_fl, np.einsum("nij,nj->ni", R_c[mi], pc))
    cols = np.concatenate([np.zeros(n_x, bool), used[n_x:]])
    for m in range(Mk):
        cols[12 * m + 9 : 12 * m + 12] = True
    sol2, *_ = np.linalg.lstsq(
        A.reshape(3 * N, -1)[:, cols], rhs.reshape(-1), rcond=None
    )
    full = np.zeros(n_x + n_b)
    full[cols] = sol2
    t_c = np.stack([full[12 * m + 9 : 12 * m + 12] for m in range(Mk)])
    R_b = np.zeros((S, 3, 3))
    t_b = np.zeros((S, 3))
    loose = []
    for s in range(S):
        seen = [k for k in range(K) if np.any(key == s * K + k)]
        b_base = np.array(
            [full[n_x + 3 * (s * K + k) : n_x + 3 * (s * K + k) + 3] for k in seen]
        )
        # Fewer than 3 (or collinear) targets leave a rotation free: the one nearest the
        # nominal (identity) that fits them.
        R_b[s], t_b[s], determined = rigid_fit_nearest(
            b_base, meas.targets[seen], np.eye(3)
        )
        if not determined:
            loose.append(s)
    return R_b, t_b, R_c, t_c, loose


def euler_with_reference(R: Float) -> tuple[Float, Float]:
    """Reference rotation and Euler angles: identity unless near gimbal lock."""
    rwp = matrix_to_euler_zyx(R)
    if abs(abs(rwp[1]) - np.pi / 2) < _GIMBAL_MARGIN:
        return R.copy(), np.zeros(3)
    return np.eye(3), rwp


def initial_frames(
    model: CalibrationModel, params: Float, meas: Measurements
) -> tuple[CalibrationModel, Float]:
    """Starting user and cam frames from the kinematics in ``params``.

    Returns
    -------
    model : CalibrationModel
        The same model, with reference rotations where a frame is near gimbal lock.
    params : (P,) the parameters with every user and cam frame set.
    """
    out, x, _ = closed_form_frames(model, params, meas)
    return out, x


def closed_form_frames(
    model: CalibrationModel,
    params: Float,
    meas: Measurements,
    flange: Flange | None = None,
) -> tuple[CalibrationModel, Float, list[int]]:
    """:func:`initial_frames`, and the sets whose data do not fix their user frame's
    rotation (one point, or all on one line). ``flange``: the flange frames of
    ``params`` where already evaluated (in the model base, ``(R, o)``)."""
    x = params.copy()
    R_ref_b = model.R_ref_base.copy()
    R_ref_c = model.R_ref_cam.copy()
    # Frames are evaluated with identity reference rotations and zero user frames.
    work = model.with_references(np.broadcast_to(np.eye(3), R_ref_b.shape))
    base_idx = work.base_index
    x[base_idx] = 0.0
    if meas.kind == "point":
        R_b, t_b, tool, loose = _init_point(work, x, meas, flange=flange)
        R_c, t_c = None, tool
    elif meas.kind == "pose":
        R_b, t_b, R_c, t_c = _init_pose(work, x, meas, flange)
        loose = []
    else:
        R_b, t_b, R_c, t_c, loose = _init_sensor(work, x, meas, flange)
    for s in range(len(model.spec.sets)):
        R_ref_b[s], rwp = euler_with_reference(R_b[s])
        x[base_idx[s]] = np.concatenate([t_b[s], rwp])
    cam_idx = model.cam_index
    for m in range(len(model.spec.markers)):
        x[cam_idx[m, :3]] = t_c[m]
        if model.spec.cam_rotation and R_c is not None:
            R_ref_c[m], rwp = euler_with_reference(R_c[m])
            x[cam_idx[m, 3:]] = rwp
    out = model.with_references(R_ref_b, R_ref_c if model.spec.cam_rotation else None)
    return out, x, loose


def _set_name(label: str) -> str:
    """``set 'A'``, or the default set (data without a set column) in words."""
    return f"set {label!r}" if label else "the data (one set)"


def _rows(n: int) -> str:
    return f"{n} row{'s' if n != 1 else ''}"
