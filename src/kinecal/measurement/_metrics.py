"""Accuracy metrics of Tables 5 and 8: RMS, Std, Avg, Max of 3-D position error norms.

``Std`` is the population standard deviation of the norms, so ``RMS^2 = Avg^2 + Std^2``
holds exactly (it does for the paper's tables to their printed precision).
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields

import numpy as np

from kinecal._record import Record
from kinecal.typing import Float

__all__ = ["Metrics", "metrics_from_errors"]


@dataclass(frozen=True, eq=False, repr=False)
class Metrics(Record):
    """Error statistics of a set of poses (mm, deg).

    Attributes
    ----------
    n : number of poses.
    rms_mm, std_mm, mean_mm, max_mm : of the 3-D position error norms.
    rms_xyz_mm : RMS of the error along x, y, z of the user frame.
    rot_rms_deg, rot_max_deg : of the orientation errors (pose data), else None.
    norms_mm : the 3-D position error norm of every pose (N,) when the metrics were
        computed from errors (:func:`metrics_from_errors`), so that statistics over
        several sets of poses (the percentiles of all held-out folds) can be pooled;
        not part of the comparison nor of :meth:`as_dict`.
    """

    n: int
    rms_mm: float
    std_mm: float
    mean_mm: float
    max_mm: float
    rms_xyz_mm: tuple[float, float, float]
    rot_rms_deg: float | None = None
    rot_max_deg: float | None = None
    norms_mm: np.ndarray | None = field(default=None, repr=False, compare=False)

    def as_dict(self) -> dict[str, object]:
        return {
            f.name: getattr(self, f.name) for f in fields(self) if f.name != "norms_mm"
        }

    def contract(self) -> dict[str, float | int]:
        """The object ``kinecal evaluate --json`` prints: ``n, rms_mm, std_mm, mean_mm,
        max_mm``, and ``rot_rms_deg`` for pose data."""
        out: dict[str, float | int] = {
            "n": self.n,
            "rms_mm": self.rms_mm,
            "std_mm": self.std_mm,
            "mean_mm": self.mean_mm,
            "max_mm": self.max_mm,
        }
        if self.rot_rms_deg is not None:
            out["rot_rms_deg"] = self.rot_rms_deg
        return out


def metrics_from_errors(e_pos_m: Float, e_rot_rad: Float | None = None) -> Metrics:
    """Metrics of position errors (N, 3) [m] and optional rotation errors (N, 3) [rad]."""
    e = np.asarray(e_pos_m, dtype=np.float64) * 1e3
    if e.ndim != 2 or e.shape[1] != 3:
        raise ValueError(f"e_pos_m must have shape (N, 3); got {e.shape}.")
    if e.shape[0] == 0:
        nan = float("nan")
        return Metrics(0, nan, nan, nan, nan, (nan, nan, nan), norms_mm=np.empty(0))
    d = np.linalg.norm(e, axis=1)
    rot_rms = rot_max = None
    if e_rot_rad is not None:
        a = np.degrees(np.linalg.norm(e_rot_rad, axis=1))
        rot_rms, rot_max = float(np.sqrt(np.mean(a * a))), float(a.max())
    xyz = np.sqrt(np.mean(e * e, axis=0))
    return Metrics(
        n=int(d.size),
        rms_mm=float(np.sqrt(np.mean(d * d))),
        std_mm=float(np.std(d)),
        mean_mm=float(np.mean(d)),
        max_mm=float(d.max()),
        rms_xyz_mm=(float(xyz[0]), float(xyz[1]), float(xyz[2])),
        rot_rms_deg=rot_rms,
        rot_max_deg=rot_max,
        norms_mm=d,
    )
