"""Issues 6 and 24 end to end: calibrate the simulated sensor from images (one bundle
adjustment), scan the four ceramic spheres through it.

Radius errors are compared with the paper's Fig. 10 (RMS 0.0114 mm, Std 0.0049 mm).
"""

from __future__ import annotations

import numpy as np
import pytest

from kinecal.sensor import INTRINSICS, StripeRenderer, fit_sphere, sphere_scene
from kinecal.simulation import CERAMIC_SPHERES_MM

pytestmark = pytest.mark.slow


def test_issue_24_calibration_std_cover_the_truth(calibrated_sensor):
    """k3 not estimated (not determined by this narrow lens); every estimated intrinsic
    within 3 reported std of the truth; every light plane fitted on its own within 4 std
    at its points; re-projection and plane-fit errors at the paper's scale (0.06 px,
    0.004 mm)."""
    res = calibrated_sensor.result
    true = calibrated_sensor.true
    cc, pc = res.camera, res.planes
    print(
        f"re-projection {cc.rms_px:.4f} px, plane fit {pc.mean_rms_mm:.4f} mm, "
        f"stripe std {res.sigma_stripe_px:.3f} px, k3 test {cc.k3_test}"
    )
    assert cc.rms_px < 0.06 and pc.mean_rms_mm < 0.006
    assert "k3" in cc.fixed
    z = {
        k: (getattr(cc.camera, k) - getattr(true.camera, k)) / cc.std[k]
        for k in INTRINSICS
        if k not in ("k1", "k2", "k3")  # k1, k2 take up the fixed k3: effective values
    }
    print("intrinsics z", {k: round(v, 2) for k, v in z.items()})
    assert all(abs(v) < 3 for v in z.values()), z
    b = res.bundle
    sp = b.stripes
    assert sp is not None
    zs = []
    for i in np.flatnonzero(np.array(pc.status) == "free"):
        sel = sp.plane == i
        r = cc.camera.rays(sp.uv[sel])
        m = b.T_cam_board[sp.view[sel], :3, 2]
        d = np.einsum("ij,ij->i", m, b.T_cam_board[sp.view[sel], :3, 3])
        X0 = (r * (d / np.einsum("ij,ij->i", m, r))[:, None]).mean(axis=0)
        X0 -= (X0 @ b.n[i] + b.b[i]) * b.n[i]
        zs.append(true.planes.distance(X0, i) / b.plane_std_m[i])
    zs = np.array(zs)
    print(f"planes: {zs.size} free, RMS z {np.sqrt(np.mean(zs**2)):.2f}")
    assert np.sqrt(np.mean(zs**2)) < 2.0 and np.all(np.abs(zs) < 4.5)


def test_four_ceramic_spheres_through_the_calibrated_sensor(calibrated_sensor):
    """Radius errors at the paper's scale, and (issue 24) every centre within 40 um of
    the truth (it was 0.21 mm with k3 = -12 from the camera-only calibration)."""
    true, cal = calibrated_sensor.true, calibrated_sensor.calibrated
    rng = np.random.default_rng(2025)
    ren = StripeRenderer(true.camera, true.planes)
    radius_err, centres = [], []
    for R in CERAMIC_SPHERES_MM[:, 3] * 1e-3:
        for _ in range(2):
            c = np.array(
                [
                    rng.uniform(-2e-3, 2e-3),
                    rng.uniform(-2e-3, 2e-3),
                    rng.uniform(0.135, 0.145),
                ]
            )
            cloud = cal.scan(ren.render_scan(sphere_scene(c, R), rng))
            f = fit_sphere(cloud.points)
            radius_err.append(f.radius - R)
            centres.append(f.center - c)
    e = np.array(radius_err)
    rms, std = np.sqrt(np.mean(e**2)), np.std(e)
    d = np.array(centres)
    print(
        f"radius error RMS {rms * 1e3:.4f} mm, Std {std * 1e3:.4f} mm (paper 0.0114 / "
        f"0.0049); centre errors [um] {np.round(d * 1e6, 1).tolist()}"
    )
    assert rms < 0.03e-3 and std < 0.015e-3  # the paper's scale
    assert np.all(np.linalg.norm(d, axis=1) < 40e-6)
