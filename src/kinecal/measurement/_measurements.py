"""Measurements: what was measured at each pose, in SI (DESIGN §7).

Three kinds, one per data set:

* ``point``  - a point on the tool (reflector) measured in the user frame (laser tracker);
* ``pose``   - the point plus the tool orientation (6-D tracker, motion capture);
* ``sensor`` - a fixed target (sphere centre, known in the user frame) measured in the cam
  frame: the model maps the measurement into the user frame (Eq. 6).

Rows carry a session (``set``: own user frame), a tool marker (own cam frame), an optional
payload and optional standard deviations used as weights.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from kinecal._record import Record
from kinecal._stats import median
from kinecal.errors import DataError
from kinecal.models import ModelInputs
from kinecal.typing import ArrayLike, Float

__all__ = ["KINDS", "Measurements"]

KINDS = ("point", "pose", "sensor")


@dataclass(frozen=True, eq=False, repr=False)
class Measurements(Record):
    """A calibration or test data set (SI units).

    Attributes
    ----------
    kind : {'point', 'pose', 'sensor'}
    q_ctrl : (N, n) controller joint values [rad; m for prismatic joints].
    p : (N, 3) measured point: in the user frame (point, pose) or the cam frame (sensor) [m].
    R_user_cam : (N, 3, 3) or None, measured orientation (pose data).
    target_index : (N,) int or None, which target each sensor row saw.
    targets : (K, 3) or None, target positions in the user frame [m] (sensor data).
    target_labels : tuple of str, names of the targets.
    set_index, marker_index : (N,) int, indices into ``set_labels``, ``marker_labels``.
    sigma : (N,) or None, position standard deviation per row [m].
    sigma_rot : (N,) or None, orientation standard deviation per row [rad].
    payload_kg : (N,) or None, payload of each row.
    rows : (N,) int, row numbers in the source file (1-based data rows) for reports.
    source : str, where the data came from.
    """

    kind: str
    q_ctrl: Float
    p: Float
    R_user_cam: Float | None = None
    target_index: np.ndarray | None = None
    targets: Float | None = None
    target_labels: tuple[str, ...] = ()
    set_index: np.ndarray = field(default_factory=lambda: np.zeros(0, np.intp))
    set_labels: tuple[str, ...] = ("",)
    marker_index: np.ndarray = field(default_factory=lambda: np.zeros(0, np.intp))
    marker_labels: tuple[str, ...] = ("",)
    sigma: Float | None = None
    sigma_rot: Float | None = None
    payload_kg: Float | None = None
    rows: np.ndarray = field(default_factory=lambda: np.zeros(0, np.intp))
    source: str = "<array>"

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise DataError(
                f"{self.source}: kind must be one of {KINDS}; got {self.kind!r}."
            )
        q = np.asarray(self.q_ctrl, dtype=np.float64)
        if q.ndim != 2:
            raise DataError(
                f"{self.source}: q_ctrl must have shape (N, n); got {q.shape}."
            )
        N = q.shape[0]
        object.__setattr__(self, "q_ctrl", q)
        object.__setattr__(
            self, "p", np.asarray(self.p, dtype=np.float64).reshape(N, 3)
        )
        for name in ("set_index", "marker_index", "rows"):
            v = np.asarray(getattr(self, name), dtype=np.intp)
            if v.size == 0:
                v = (
                    np.arange(1, N + 1, dtype=np.intp)
                    if name == "rows"
                    else np.zeros(N, np.intp)
                )
            if v.shape != (N,):
                raise DataError(f"{self.source}: {name} must have one entry per row.")
            object.__setattr__(self, name, v)
        if N and (
            self.set_index.max() >= len(self.set_labels) or self.set_index.min() < 0
        ):
            raise DataError(f"{self.source}: set_index out of range of set_labels.")
        if N and (
            self.marker_index.max() >= len(self.marker_labels)
            or self.marker_index.min() < 0
        ):
            raise DataError(
                f"{self.source}: marker_index out of range of marker_labels."
            )
        if self.kind == "pose" and self.R_user_cam is None:
            raise DataError(
                f"{self.source}: pose data needs orientations (qw, qx, qy, qz)."
            )
        if self.kind == "sensor" and (
            self.targets is None or self.target_index is None
        ):
            raise DataError(
                f"{self.source}: sensor data needs targets and target_index."
            )
        for name in ("sigma", "sigma_rot", "payload_kg"):
            raw = getattr(self, name)
            if raw is not None:
                fv = np.asarray(raw, dtype=np.float64).reshape(N)
                low = fv < 0 if name == "payload_kg" else fv <= 0  # 0 kg: no payload
                if np.any(~np.isfinite(fv)) or np.any(low):
                    what = ">= 0" if name == "payload_kg" else "positive"
                    raise DataError(f"{self.source}: {name} must be {what} and finite.")
                object.__setattr__(self, name, fv)
        for name in ("q_ctrl", "p"):
            if not np.all(np.isfinite(getattr(self, name))):
                raise DataError(
                    f"{self.source}: {name} contains NaN or infinite values."
                )

    # ------------------------------------------------------------------ basics
    @property
    def n(self) -> int:
        return int(self.q_ctrl.shape[0])

    @property
    def n_joints(self) -> int:
        return int(self.q_ctrl.shape[1])

    @property
    def components(self) -> int:
        """Residual components per row: 3 (point, sensor) or 6 (pose)."""
        return 6 if self.kind == "pose" else 3

    def pose_groups(self) -> np.ndarray:
        """A label per row, shared by the rows of one set measured at the same joint
        values (several markers seen at one pose), numbered by first appearance."""
        from kinecal._stats import row_groups

        return row_groups(np.column_stack([self.set_index, np.round(self.q_ctrl, 9)]))

    def subset(self, rows: ArrayLike) -> Measurements:
        """The measurements of the selected rows (indices or boolean mask)."""
        idx = np.asarray(rows)
        if idx.dtype == bool:
            idx = np.flatnonzero(idx)

        def take(v: np.ndarray | None) -> np.ndarray | None:
            return None if v is None else v[idx]

        return replace(
            self,
            q_ctrl=self.q_ctrl[idx],
            p=self.p[idx],
            R_user_cam=take(self.R_user_cam),
            target_index=take(self.target_index),
            set_index=self.set_index[idx],
            marker_index=self.marker_index[idx],
            sigma=take(self.sigma),
            sigma_rot=take(self.sigma_rot),
            payload_kg=take(self.payload_kg),
            rows=self.rows[idx],
        )

    def reference_payload(self) -> float | None:
        """The payload that defines the unit weight of lambda*: the median of the rows
        with a payload (rows of 0 kg have none; None if no row has one)."""
        if self.payload_kg is None or not np.any(self.payload_kg > 0):
            return None
        return median(self.payload_kg[self.payload_kg > 0])

    def model_inputs(self, reference_payload_kg: float | None = None) -> ModelInputs:
        """Per-sample inputs of the calibration model."""
        p_cam = self.p if self.kind == "sensor" else None
        load = None
        if self.payload_kg is not None:
            ref = reference_payload_kg or self.reference_payload() or 1.0
            load = self.payload_kg / ref
        return ModelInputs.make(
            self.q_ctrl,
            set_index=self.set_index,
            marker_index=self.marker_index,
            p_cam=p_cam,
            load_scale=load,
        )

    def reference_points(self) -> Float:
        """What the model's prediction is compared with, in the user frame (N, 3) [m]."""
        if self.kind == "sensor":
            assert self.targets is not None and self.target_index is not None
            return self.targets[self.target_index]
        return self.p
