"""Issue 6 end to end: calibrate the simulated sensor from images, scan the four spheres.

Radius errors are compared with the paper's Fig. 10 (RMS 0.0114 mm, Std 0.0049 mm).
"""

from __future__ import annotations

import numpy as np
import pytest

from kinecal.sensor import StripeRenderer, fit_sphere, sphere_scene
from kinecal.simulation import CERAMIC_SPHERES_MM

pytestmark = pytest.mark.slow


def test_four_ceramic_spheres_through_the_calibrated_sensor(calibrated_sensor):
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
    print(
        f"radius error RMS {rms * 1e3:.4f} mm, Std {std * 1e3:.4f} mm (paper 0.0114 / 0.0049)"
    )
    assert rms < 0.03e-3 and std < 0.015e-3  # the paper's scale
    d = np.array(centres)
    # The calibrated sensor's centre error is mostly a constant offset (absorbed by the
    # hand-eye frame); what varies between scans must stay at the tens-of-um level.
    assert np.all(np.std(d, axis=0) < 40e-6), np.std(d, axis=0)
