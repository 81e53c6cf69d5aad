"""Camera model against OpenCV, light-plane geometry, reconstruction (Eq. 1-5)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from kinecal.errors import ConfigError, DataError
from kinecal.sensor import (
    Camera,
    LightPlanes,
    Sensor,
    fit_plane,
    intersect_planes,
    paper_camera,
    paper_sensor,
    rotary_planes,
)


def _points(rng, n=500):
    return np.column_stack(
        [
            rng.uniform(-0.03, 0.03, n),
            rng.uniform(-0.02, 0.02, n),
            rng.uniform(0.11, 0.14, n),
        ]
    )


def test_projection_matches_opencv():
    cam = paper_camera()
    P = _points(np.random.default_rng(0))
    uv_cv, _ = cv2.projectPoints(P, np.zeros(3), np.zeros(3), cam.K, cam.dist)
    np.testing.assert_allclose(cam.project(P), uv_cv.reshape(-1, 2), atol=1e-9)


def test_undistort_inverts_distort_and_matches_opencv():
    cam = paper_camera()
    P = _points(np.random.default_rng(1))
    uv = cam.project(P)
    xy = cam.normalised(uv)
    np.testing.assert_allclose(xy, P[:, :2] / P[:, 2:], atol=1e-13)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-15)
    ref = cv2.undistortPointsIter(
        uv.reshape(-1, 1, 2), cam.K, cam.dist, None, None, crit
    ).reshape(-1, 2)
    np.testing.assert_allclose(xy, ref, atol=1e-9)


def test_batched_shapes():
    cam = paper_camera()
    P = _points(np.random.default_rng(2), 24).reshape(2, 3, 4, 3)
    assert cam.project(P).shape == (2, 3, 4, 2)
    assert cam.rays(cam.project(P)).shape == (2, 3, 4, 3)


def test_camera_validation_and_round_trip():
    cam = paper_camera()
    assert Camera.from_dict(cam.to_dict()) == cam
    assert Camera.from_opencv(cam.K, cam.dist, (cam.width, cam.height)) == cam
    with pytest.raises(ConfigError, match="focal"):
        Camera(fx=-1, fy=1, u0=0, v0=0)
    with pytest.raises(ConfigError, match="unknown key"):
        Camera.from_dict({**cam.to_dict(), "fz": 1.0})


def test_rotary_planes_geometry():
    pl = rotary_planes()
    assert len(pl) == 120
    S = pl.source
    # every plane contains the mirror axis (through S along y) ...
    for y in (-0.05, 0.0, 0.05):
        np.testing.assert_allclose(
            pl.distance(S + np.array([0, y, 0]), np.arange(120)), 0, atol=1e-15
        )
    # ... the middle planes cross the optical axis near the working distance ...
    z = -pl.b / pl.n[:, 2]
    assert 0.115 < z[60] < 0.135 and min(z[59], z[60]) < 0.125 < max(z[59], z[60])
    # ... and the sweep is 20 degrees.
    sweep = np.degrees(np.arccos(pl.n[0] @ pl.n[-1]))
    assert sweep == pytest.approx(20.0, abs=1e-9)


def test_reconstruction_eq_4_5_closed_form_equals_matrix_form():
    sen = paper_sensor()
    rng = np.random.default_rng(3)
    idx = rng.integers(0, 120, 300)
    uv = np.column_stack([rng.uniform(0, 1279, 300), rng.uniform(0, 1023, 300)])
    X = sen.reconstruct(uv, idx)
    # Eq. (5) literally, on undistorted pixels: X = A^-1 (0, 0, -b)
    cam = sen.camera
    xy = cam.normalised(uv)
    u = cam.fx * xy[:, 0] + cam.u0
    v = cam.fy * xy[:, 1] + cam.v0
    A = np.zeros((300, 3, 3))
    A[:, 0, 0], A[:, 0, 2] = cam.fx, cam.u0 - u
    A[:, 1, 1], A[:, 1, 2] = cam.fy, cam.v0 - v
    A[:, 2] = sen.planes.n[idx]
    rhs = np.zeros((300, 3))
    rhs[:, 2] = -sen.planes.b[idx]
    np.testing.assert_allclose(
        X, np.linalg.solve(A, rhs[..., None])[..., 0], atol=1e-12
    )
    # and the points project back onto their pixels and lie on their planes
    np.testing.assert_allclose(cam.project(X), uv, atol=1e-8)
    np.testing.assert_allclose(sen.planes.distance(X, idx), 0, atol=1e-15)


def test_reconstruction_rejects_unknown_plane():
    sen = paper_sensor()
    with pytest.raises(DataError, match="out of range"):
        sen.reconstruct(np.zeros((1, 2)), np.array([120]))


def test_fit_plane_and_parallel_rays():
    rng = np.random.default_rng(4)
    n = np.array([0.3, -0.2, 0.9])
    n /= np.linalg.norm(n)
    P = rng.normal(size=(200, 3)) * 0.01
    P -= np.outer(P @ n + (-0.1), n)  # onto n.X - 0.1 = 0
    nn, b, rms = fit_plane(P + rng.normal(size=P.shape) * 1e-7)
    assert abs(abs(nn @ n) - 1) < 1e-8 and abs(abs(b) - 0.1) < 1e-7 and rms < 2e-7
    with pytest.raises(DataError, match="collinear"):
        fit_plane(np.outer(np.arange(5.0), [1, 2, 3]))
    pl = LightPlanes(np.array([[1.0, 0, 0]]), np.array([-0.05]))
    X = intersect_planes(pl, np.array([[0.0, 1.0, 1.0]]), np.array([0]))
    assert np.all(np.isnan(X))


def test_sensor_dict_round_trip():
    sen = paper_sensor()
    back = Sensor.from_dict(sen.to_dict())
    assert back.camera == sen.camera
    np.testing.assert_allclose(back.planes.n, sen.planes.n, atol=1e-15)
    np.testing.assert_allclose(back.planes.b, sen.planes.b, atol=1e-15)


# -- issue 24: analytic Jacobians of the camera model (the bundle adjustment's) ---------


def _camera_scales(cam):
    """A step scale per intrinsic (fx.. in px, distortion dimensionless)."""
    return np.array([100.0, 100.0, 10.0, 10.0, 0.1, 0.1, 0.1, 1e-3, 1e-3])


def test_projection_jacobians_match_finite_differences():
    from kinecal.sensor import INTRINSICS
    from tests.helpers import assert_jacobian_matches_fd

    cam = paper_camera().with_(p1=0.002, p2=-0.003)
    P = _points(np.random.default_rng(5), 12)
    uv, J_P, J_c = cam.project_jacobian(P)
    np.testing.assert_allclose(uv, cam.project(P), atol=1e-12)
    for k in range(P.shape[0]):
        assert_jacobian_matches_fd(
            J_P[k], lambda p, k=k: cam.project(p), P[k], rtol=1e-6
        )
    sc = _camera_scales(cam)
    c0 = cam.intrinsics()
    np.testing.assert_allclose(cam.with_intrinsics(c0).intrinsics(), c0, atol=0)
    assert_jacobian_matches_fd(
        J_c * sc,
        lambda x: cam.with_intrinsics(c0 + x * sc).project(P),
        np.zeros(9),
        names=list(INTRINSICS),
    )


def test_undistortion_jacobians_match_finite_differences():
    """Implicit differentiation through the Newton undistortion (Eq. 2 inverted)."""
    from kinecal.sensor import INTRINSICS
    from tests.helpers import assert_jacobian_matches_fd

    cam = paper_camera().with_(p1=0.002, p2=-0.003)
    rng = np.random.default_rng(6)
    uv = np.column_stack([rng.uniform(0, 1279, 15), rng.uniform(0, 1023, 15)])
    xy, J_c, J_uv = cam.normalised_jacobian(uv)
    np.testing.assert_allclose(xy, cam.normalised(uv), atol=0)
    sc = _camera_scales(cam)
    c0 = cam.intrinsics()
    assert_jacobian_matches_fd(
        J_c * sc,
        lambda x: cam.with_intrinsics(c0 + x * sc).normalised(uv),
        np.zeros(9),
        names=list(INTRINSICS),
    )
    for k in range(3):
        assert_jacobian_matches_fd(J_uv[k], lambda p: cam.normalised(p), uv[k])
