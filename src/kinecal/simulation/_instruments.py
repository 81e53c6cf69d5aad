"""Measurement models of the digital twin: laser tracker, 6-D tracker, sphere sensor.

All noise is drawn from a caller's ``numpy.random.Generator`` (seeded runs are exact).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kinecal.geometry import so3_exp
from kinecal.typing import Float

__all__ = ["LaserTracker", "PoseTracker", "SphereSensor", "add_outliers"]


@dataclass(frozen=True)
class LaserTracker:
    """Point measurements with noise growing with distance from the tracker head.

    The per-axis standard deviation is ``sigma0 + per_m · distance``. The default is an
    API T3-class tracker: the maker's 15 um + 6 um/m taken as a 2-sigma bound.
    """

    sigma0: float = 7.5e-6
    per_m: float = 3e-6

    def measure(self, p_user: Float, rng: np.random.Generator) -> tuple[Float, Float]:
        """Noisy points (N, 3) and the per-axis sigma of each (N,) [m]."""
        dist = np.linalg.norm(p_user, axis=1)
        sigma = self.sigma0 + self.per_m * dist
        return p_user + rng.normal(size=p_user.shape) * sigma[:, None], sigma


@dataclass(frozen=True)
class PoseTracker:
    """6-D tracker (T-Mac, motion capture): position and orientation noise."""

    sigma_pos: float = 20e-6
    sigma_rot: float = 2e-5  # rad

    def measure(
        self, p_user: Float, R_user: Float, rng: np.random.Generator
    ) -> tuple[Float, Float]:
        p = p_user + rng.normal(size=p_user.shape) * self.sigma_pos
        R = so3_exp(rng.normal(size=p_user.shape) * self.sigma_rot) @ R_user
        return p, R


@dataclass(frozen=True)
class SphereSensor:
    """Sphere centres seen by the 3D rotary laser sensor, a fast point-level model.

    The centre comes from a least-squares sphere fit to a dense cap of points, so its error
    is small across the optical axis and larger along it (the stripes see the cap from one
    side). Defaults match the paper's sensor (radius RMS 11 um, Fig. 10).
    """

    sigma_xy: float = 4e-6
    sigma_z: float = 8e-6

    def measure(self, p_cam: Float, rng: np.random.Generator) -> Float:
        noise = rng.normal(size=p_cam.shape) * np.array(
            [self.sigma_xy, self.sigma_xy, self.sigma_z]
        )
        return p_cam + noise


def add_outliers(
    p: Float, rng: np.random.Generator, fraction: float, size: float = 1e-3
) -> tuple[Float, np.ndarray]:
    """Gross errors of ~``size`` [m] on a random ``fraction`` of rows; returns their indices."""
    n = p.shape[0]
    k = round(fraction * n)
    idx = np.sort(rng.choice(n, size=k, replace=False)) if k else np.zeros(0, np.intp)
    out = p.copy()
    d = rng.normal(size=(k, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    out[idx] += d * size * rng.uniform(1.0, 3.0, size=(k, 1))
    return out, idx
