"""SO(3)/SE(3) helpers: round trips over batch shapes, near identity and near pi, against scipy."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.spatial.transform import Rotation

from kinecal.geometry import (
    euler_transform,
    euler_zyx_to_matrix,
    make_transform,
    matrix_to_euler_zyx,
    matrix_to_quat_wxyz,
    matrix_to_wpr,
    project_to_so3,
    quat_wxyz_to_matrix,
    rot_x,
    rot_y,
    rot_z,
    se3_exp,
    se3_log,
    skew,
    so3_exp,
    so3_left_jacobian,
    so3_log,
    so3_right_jacobian_inv,
    transform_inv,
    transform_points,
    transform_to_euler,
    wpr_to_matrix,
)
from tests.helpers import assert_jacobian_matches_fd
from tests.tolerances import ROUND_TRIP

SHAPES = [(), (1,), (3, 2)]
finite = st.floats(-10, 10, allow_nan=False, allow_infinity=False)


def _rotvecs(shape, scale):
    return arrays(np.float64, (*shape, 3), elements=st.floats(-1, 1)).map(
        lambda a: a * scale
    )


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("scale", [1e-7, 1.0, 3.0])
@settings(max_examples=40, deadline=None)
@given(data=st.data())
def test_so3_exp_log_round_trip(shape, scale, data):
    w = data.draw(_rotvecs(shape, scale))
    w = np.where(np.linalg.norm(w, axis=-1, keepdims=True) > np.pi - 1e-9, w * 0.5, w)
    R = so3_exp(w)
    assert R.shape == (*shape, 3, 3)
    np.testing.assert_allclose(so3_log(R), w, atol=1e-10)
    np.testing.assert_allclose(
        R @ np.swapaxes(R, -1, -2), np.broadcast_to(np.eye(3), R.shape), atol=1e-13
    )


def test_so3_matches_scipy(rng):
    R = Rotation.random(2000, random_state=rng).as_matrix()
    np.testing.assert_allclose(
        so3_log(R), Rotation.from_matrix(R).as_rotvec(), atol=1e-12
    )
    w = Rotation.from_matrix(R).as_rotvec()
    np.testing.assert_allclose(so3_exp(w), R, atol=1e-13)


def test_so3_log_near_pi(rng):
    axis = rng.normal(size=(200, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    for eps in (0.0, 1e-12, 1e-7, 1e-3, 0.05):
        R = so3_exp(axis * (np.pi - eps))
        np.testing.assert_allclose(so3_exp(so3_log(R)), R, atol=1e-12)


def test_elementary_rotations_match_scipy(rng):
    a = rng.uniform(-4, 4, size=50)
    for f, ax in ((rot_x, "x"), (rot_y, "y"), (rot_z, "z")):
        np.testing.assert_allclose(
            f(a), Rotation.from_euler(ax, a[:, None]).as_matrix(), atol=1e-15
        )


def test_skew_is_cross_product(rng):
    # Eq. (20)
    v, u = rng.normal(size=(2, 10, 3))
    np.testing.assert_allclose(
        skew(v) @ u[..., None], np.cross(v, u)[..., None], atol=1e-14
    )


@pytest.mark.parametrize("shape", SHAPES)
def test_euler_zyx_round_trip_and_convention(shape, rng):
    rwp = rng.uniform(
        [-np.pi, -np.pi / 2, -np.pi], [np.pi, np.pi / 2, np.pi], size=(*shape, 3)
    )
    R = euler_zyx_to_matrix(rwp)
    # Eq. (8): Rz(r) Ry(w) Rx(p), intrinsic ZYX == scipy 'ZYX' with angles (r, w, p).
    ref = Rotation.from_euler("ZYX", rwp.reshape(-1, 3)).as_matrix().reshape(R.shape)
    np.testing.assert_allclose(R, ref, atol=1e-14)
    np.testing.assert_allclose(matrix_to_euler_zyx(R), rwp, atol=1e-10)
    np.testing.assert_allclose(
        R, rot_z(rwp[..., 0]) @ rot_y(rwp[..., 1]) @ rot_x(rwp[..., 2]), atol=1e-14
    )


def test_euler_gimbal_lock_keeps_rotation():
    for w in (np.pi / 2, -np.pi / 2):
        R = euler_zyx_to_matrix(np.array([0.3, w, -0.7]))
        np.testing.assert_allclose(
            euler_zyx_to_matrix(matrix_to_euler_zyx(R)), R, atol=1e-12
        )


def test_euler_transform_round_trip(rng):
    v = np.concatenate(
        [rng.normal(size=(20, 3)), rng.uniform(-1.5, 1.5, size=(20, 3))], axis=1
    )
    T = euler_transform(v)
    np.testing.assert_allclose(transform_to_euler(T), v, atol=1e-12)
    # Trans(x, y, z) applied after the rotation (Eq. 8)
    np.testing.assert_allclose(T[:, :3, 3], v[:, :3])


def test_fanuc_wpr_convention():
    # FANUC: R = Rz(R) Ry(P) Rx(W); the faceplate at all-zero joints is W 180, P -90, R 0.
    wpr = np.radians([164.0019, 44.1360, 129.8511])
    R = wpr_to_matrix(wpr)
    np.testing.assert_allclose(
        R, rot_z(wpr[2]) @ rot_y(wpr[1]) @ rot_x(wpr[0]), atol=1e-15
    )
    np.testing.assert_allclose(matrix_to_wpr(R), wpr, atol=1e-12)


@pytest.mark.parametrize("shape", SHAPES)
def test_quaternion_round_trip_and_scipy(shape, rng):
    R = (
        Rotation.random(int(np.prod(shape)) or 1, random_state=rng)
        .as_matrix()
        .reshape(*shape, 3, 3)
    )
    q = matrix_to_quat_wxyz(R)
    assert q.shape == (*shape, 4)
    assert np.all(q[..., 0] >= 0)
    np.testing.assert_allclose(quat_wxyz_to_matrix(q), R, atol=1e-14)
    ref = Rotation.from_matrix(R.reshape(-1, 3, 3)).as_quat(scalar_first=True)
    ref *= np.sign(ref[:, :1] + 1e-300)
    np.testing.assert_allclose(q.reshape(-1, 4), ref, atol=1e-13)


def test_quaternion_half_turns_and_identity():
    for R in (np.eye(3), rot_x(np.pi), rot_y(np.pi), rot_z(np.pi), rot_x(1e-7)):
        np.testing.assert_allclose(
            quat_wxyz_to_matrix(matrix_to_quat_wxyz(R)), R, atol=1e-14
        )
    with pytest.raises(ValueError, match="zero quaternion"):
        quat_wxyz_to_matrix(np.zeros(4))


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("scale", [1e-7, 1.0])
def test_se3_round_trips(shape, scale, rng):
    xi = rng.normal(size=(*shape, 6)) * scale
    T = se3_exp(xi)
    np.testing.assert_allclose(se3_log(T), xi, atol=1e-11)
    eye = np.broadcast_to(np.eye(4), T.shape)
    np.testing.assert_allclose(T @ transform_inv(T), eye, atol=ROUND_TRIP)
    p = rng.normal(size=(*shape, 3))
    np.testing.assert_allclose(
        transform_points(transform_inv(T), transform_points(T, p)), p, atol=1e-12
    )


def test_so3_jacobians_match_finite_differences(rng):
    w0 = rng.normal(size=3)

    # Left Jacobian: exp(w + d) ~ exp(J_l d) exp(w)
    def left(d):
        return so3_log(so3_exp(w0 + d) @ so3_exp(w0).T)

    assert_jacobian_matches_fd(so3_left_jacobian(w0), left, np.zeros(3))

    # Inverse right Jacobian: log(exp(w) exp(d)) ~ w + J_r^-1 d
    def right(d):
        return so3_log(so3_exp(w0) @ so3_exp(d))

    assert_jacobian_matches_fd(so3_right_jacobian_inv(w0), right, np.zeros(3))


def test_project_to_so3(rng):
    R = Rotation.random(10, random_state=rng).as_matrix()
    noisy = R + rng.normal(size=R.shape) * 1e-3
    P = project_to_so3(noisy)
    np.testing.assert_allclose(np.linalg.det(P), 1.0, atol=1e-12)
    assert np.abs(P - R).max() < 5e-3


def test_bad_shapes_are_named():
    with pytest.raises(ValueError, match=r"must have shape \(\.\.\., 3\)"):
        so3_exp(np.zeros(4))
    with pytest.raises(ValueError, match=r"T must have shape \(\.\.\., 4, 4\)"):
        transform_inv(np.zeros((4, 3)))
    with pytest.raises(ValueError, match="R must have shape"):
        make_transform(np.zeros((2, 2)), np.zeros(3))
