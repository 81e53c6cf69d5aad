"""ISO 9283 figures of measured test cycles, with a calibrated model and the nominal robot.

The *command* pose of a row is what a model predicts at the row's recorded joints: for
the nominal robot at the plan's joints this is the cube point (the joints came from its
inverse kinematics); for a calibrated model at joints compensated with it, the cube point
again; for a calibrated model at the plan's nominal joints, it is the pose compensation
would have commanded there, so the model's AP is the accuracy left after compensation.
The *attained* pose is the measured one. Both are expressed in the robot base frame
through the user frame of the calibrated model (re-estimated on the data first with
``refit``, as ``kinecal evaluate --refit`` does); the nominal robot is placed by fitting
its user and tool frames to the calibrated model's predictions over the joint ranges,
not to the test data (a fit to five test points would absorb part of the error being
measured). Details: docs/iso9283.md.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from kinecal.errors import DataError
from kinecal.identification import evaluate, refit_diagnosed
from kinecal.iso9283._characteristics import (
    MIN_CYCLES,
    DistanceFigures,
    PointFigures,
    distance_characteristics,
    pose_characteristics,
)
from kinecal.iso9283._compensate import user_from_base
from kinecal.iso9283._cube import POINT_LABELS
from kinecal.iso9283._plan import DEFAULT_CYCLES, joint_samples
from kinecal.measurement import CalibratedModel, Measurements
from kinecal.typing import ArrayLike, Float

__all__ = ["IsoEvaluation", "IsoFigures", "evaluate_iso9283", "nominal_placed"]

_PLACE_SAMPLES = 400  # joint samples over which the nominal robot is placed
_M, _DEG = 1e3, 180.0 / np.pi


@dataclass(frozen=True)
class IsoFigures:
    """ISO 9283 figures of one model (the calibrated one, or the nominal robot).

    Attributes
    ----------
    name : 'model' or 'nominal'.
    points : one :class:`PointFigures` per test point (P1..P5).
    distance : :class:`DistanceFigures` between P2 and P4, or None.
    rms : RMS of the 3-D position errors of all rows [m] (for comparison).
    """

    name: str
    points: tuple[PointFigures, ...]
    distance: DistanceFigures | None
    rms: float

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready figures in mm and deg."""
        pts = []
        for f in self.points:
            d: dict[str, Any] = {
                "point": f.label,
                "n": f.n,
                "command_mm": (f.command * _M).tolist(),
                "mean_mm": (f.mean * _M).tolist(),
                "ap_mm": f.ap * _M,
                "ap_x_mm": float(f.ap_xyz[0] * _M),
                "ap_y_mm": float(f.ap_xyz[1] * _M),
                "ap_z_mm": float(f.ap_xyz[2] * _M),
                "l_bar_mm": f.l_bar * _M,
                "s_l_mm": f.s_l * _M,
                "rp_mm": f.rp * _M,
            }
            if f.ap_abc is not None and f.rp_abc is not None:
                for k, a in enumerate("abc"):
                    d[f"ap_{a}_deg"] = float(f.ap_abc[k] * _DEG)
                    d[f"rp_{a}_deg"] = float(f.rp_abc[k] * _DEG)
            pts.append(d)
        out: dict[str, Any] = {
            "points": pts,
            "max_ap_mm": max(f.ap for f in self.points) * _M,
            "max_rp_mm": max(f.rp for f in self.points) * _M,
            "rms_mm": self.rms * _M,
            "distance": None,
        }
        if self.distance is not None:
            dd = self.distance
            out["distance"] = {
                "pair": list(dd.pair),
                "n": dd.n,
                "command_mm": dd.command * _M,
                "mean_mm": dd.mean * _M,
                "ad_mm": dd.ad * _M,
                "ad_x_mm": float(dd.ad_xyz[0] * _M),
                "ad_y_mm": float(dd.ad_xyz[1] * _M),
                "ad_z_mm": float(dd.ad_xyz[2] * _M),
                "rd_mm": dd.rd * _M,
            }
            if dd.ad_abc is not None and dd.rd_abc is not None:
                for k, a in enumerate("abc"):
                    out["distance"][f"ad_{a}_deg"] = float(dd.ad_abc[k] * _DEG)
                    out["distance"][f"rd_{a}_deg"] = float(dd.rd_abc[k] * _DEG)
        return out


@dataclass(frozen=True)
class IsoEvaluation:
    """ISO 9283 evaluation of measured test cycles.

    Attributes
    ----------
    model : figures with the calibrated model's command poses (after compensation).
    nominal : figures with the nominal robot's (before compensation), or None.
    kind : 'point' (positions) or 'pose' (with orientation).
    cycles : per point label, the number of cycles measured.
    refit : what was re-estimated on the data first ('user', 'tool').
    notes : findings worth reading (fewer cycles than the standard's 30, ...).
    """

    model: IsoFigures
    nominal: IsoFigures | None
    kind: str
    cycles: dict[str, int]
    refit: tuple[str, ...] = ()
    notes: list[str] = field(default_factory=list)

    def as_dict(self) -> dict[str, Any]:
        """The ``iso9283`` block of report.json (mm, deg)."""
        return {
            "standard": "ISO 9283:1998 (7.2 pose accuracy and repeatability, "
            "7.4 distance accuracy and repeatability)",
            "frame": "robot base (attained and command poses mapped through the "
            "calibrated model's user frame)",
            "kind": self.kind,
            "cycles": dict(self.cycles),
            "refit": list(self.refit),
            "model": self.model.as_dict(),
            "nominal": None if self.nominal is None else self.nominal.as_dict(),
            "notes": list(self.notes),
        }


def _check_labels(
    meas: Measurements, point: ArrayLike, cycle: ArrayLike
) -> tuple[np.ndarray, np.ndarray]:
    """Point indices (0 = P1) and cycles of the rows; clear errors for bad labels."""
    labels = np.asarray(point, dtype=object)
    cyc = np.asarray(cycle)
    n = meas.n
    if labels.shape != (n,) or cyc.shape != (n,):
        raise DataError(
            f"{meas.source}: one point label and one cycle per row expected "
            f"({n} rows); got {labels.shape[0] if labels.ndim else 0} labels and "
            f"{cyc.shape[0] if cyc.ndim else 0} cycles."
        )
    names = [str(s).strip().upper() for s in labels]
    for lab, row in zip(names, meas.rows):
        if lab not in POINT_LABELS:
            raise DataError(
                f"{meas.source}: line {row}: point label {lab!r} is not an ISO 9283 "
                f"test point; expected one of {', '.join(POINT_LABELS)}."
            )
    idx = np.array([POINT_LABELS.index(s) for s in names], np.intp)
    missing = [POINT_LABELS[k] for k in range(5) if not np.any(idx == k)]
    if missing:
        raise DataError(
            f"{meas.source}: no rows of test point(s) {', '.join(missing)}; the ISO 9283 "
            "pose test measures all of P1..P5 in every cycle."
        )
    few = [
        (POINT_LABELS[k], int(np.sum(idx == k)))
        for k in range(5)
        if np.sum(idx == k) < MIN_CYCLES
    ]
    if few:
        raise DataError(
            f"{meas.source}: test point {few[0][0]} has {few[0][1]} cycle; expected at "
            f"least {MIN_CYCLES} per point to compute repeatability (ISO 9283 asks for "
            f"{DEFAULT_CYCLES})."
        )
    if not np.issubdtype(cyc.dtype, np.integer):
        raise DataError(f"{meas.source}: cycles must be integers.")
    key = idx * (int(cyc.max()) + 1) + (cyc - cyc.min())
    _, first, count = np.unique(key, return_index=True, return_counts=True)
    if np.any(count > 1):
        k = first[np.argmax(count > 1)]
        raise DataError(
            f"{meas.source}: line {meas.rows[k]}: point {POINT_LABELS[idx[k]]} appears "
            f"more than once in cycle {cyc[k]}; expected one row per point and cycle."
        )
    return idx, cyc.astype(np.intp)


def _check_layout(source: str, fig: IsoFigures) -> None:
    """Refuse point labels that do not fit the test's layout: P1 the cube's centre,
    P2-P4 and P3-P5 each a diagonal through it (labels swapped, or rows of another
    test). Tolerance: 5 % of the P2-P4 distance (a nominal program's command poses)."""
    c = np.array([f.command for f in fig.points])
    tol = 0.05 * float(np.linalg.norm(c[1] - c[3]))
    off = [np.linalg.norm(c[a] + c[b] - 2.0 * c[0]) for a, b in ((1, 3), (2, 4))]
    if max(off) > tol:
        a, b = ((1, 3), (2, 4))[int(np.argmax(off))]
        raise DataError(
            f"{source}: column 'iso_point': the midpoint of {POINT_LABELS[a]} and "
            f"{POINT_LABELS[b]} is {max(off) * _M / 2:.1f} mm from P1; expected P1 at "
            "the cube's centre and P2-P4, P3-P5 on its diagonals (labels swapped? "
            "kinecal plan --iso9283 writes them)."
        )


def _to_base(cal: CalibratedModel, set_index: np.ndarray) -> tuple[Float, Float]:
    """Per row ``(R_base_user (N, 3, 3), t_base_user (N, 3))``: the robot base frame
    (the robot description's) from the user frame of each row's set."""
    frames = [user_from_base(cal, s) for s in range(len(cal.model.spec.sets))]
    R_ru = np.stack([R.T for R, _ in frames])
    t_ru = np.stack([-R.T @ t for R, t in frames])
    return R_ru[set_index], t_ru[set_index]


def nominal_placed(cal: CalibratedModel, *, seed: int = 0) -> CalibratedModel:
    """The nominal robot in ``cal``'s model structure, its user and tool frames fitted to
    ``cal``'s predictions over random joint values within the limits (every set and
    marker): the robot as the controller knows it, placed where ``cal`` says it is."""
    model = cal.model
    q = joint_samples(model.robot, _PLACE_SAMPLES, seed)
    S, K = len(model.spec.sets), len(model.spec.markers)
    si = np.repeat(np.arange(S), K * _PLACE_SAMPLES)
    mi = np.tile(np.repeat(np.arange(K), _PLACE_SAMPLES), S)
    qq = np.tile(q, (S * K, 1))
    rot = bool(model.spec.cam_rotation)
    m0 = Measurements(
        "pose" if rot else "point",
        qq,
        np.zeros((qq.shape[0], 3)),
        R_user_cam=np.broadcast_to(np.eye(3), (qq.shape[0], 3, 3)) if rot else None,
        set_index=si,
        set_labels=tuple(model.spec.sets),
        marker_index=mi,
        marker_labels=tuple(model.spec.markers),
        source="calibrated model",
    )
    out = model.evaluate(
        cal.params, m0.model_inputs(cal.reference_payload_kg), orientation=rot
    )
    from dataclasses import replace

    pseudo = replace(m0, p=out.p_user, R_user_cam=out.R_user_cam if rot else None)
    P = model.size
    start = CalibratedModel(
        model,
        model.nominal.copy(),
        np.full(P, np.nan),
        ["fixed"] * P,
        cal.reference_payload_kg,
    )
    placed, _ = refit_diagnosed(start, pseudo, ("base", "cam"))
    return placed


def _figures(
    name: str,
    cal: CalibratedModel,
    meas: Measurements,
    to_base: tuple[Float, Float],
    idx: np.ndarray,
    cyc: np.ndarray,
) -> IsoFigures:
    """AP, RP, AD, RD of ``meas`` with ``cal``'s predictions as the command poses."""
    m = cal.align(meas)
    rot = meas.kind == "pose"
    out = cal.model.evaluate(
        cal.params, m.model_inputs(cal.reference_payload_kg), orientation=rot
    )
    R_ru, t_ru = to_base
    p_att = np.einsum("nij,nj->ni", R_ru, m.p) + t_ru
    p_cmd = np.einsum("nij,nj->ni", R_ru, out.p_user) + t_ru
    R_att = R_cmd = None
    if rot:
        assert m.R_user_cam is not None and out.R_user_cam is not None
        R_att, R_cmd = R_ru @ m.R_user_cam, R_ru @ out.R_user_cam
    pts = pose_characteristics(
        p_att, p_cmd, idx, POINT_LABELS, R_attained=R_att, R_command=R_cmd
    )
    dist = distance_characteristics(
        p_att, p_cmd, idx, cyc, POINT_LABELS, R_attained=R_att, R_command=R_cmd
    )
    rms = float(np.sqrt(np.mean(np.sum((p_att - p_cmd) ** 2, axis=1))))
    return IsoFigures(name, pts, dist, rms)


def evaluate_iso9283(
    calibrated: CalibratedModel,
    meas: Measurements,
    point: Sequence[str] | ArrayLike,
    cycle: ArrayLike,
    *,
    refit: tuple[str, ...] = (),
    nominal: bool = True,
) -> IsoEvaluation:
    """ISO 9283 pose accuracy and repeatability (and distance accuracy) of measured
    test cycles, with ``calibrated``'s command poses and the nominal robot's.

    Parameters
    ----------
    calibrated : the calibrated model.
    meas : point or pose measurements of the test (one row per point and cycle).
    point : (N,) test point of each row ('P1' .. 'P5').
    cycle : (N,) int, cycle of each row.
    refit : re-estimate 'user' (and 'tool') frames on ``meas`` first, as
        :func:`kinecal.identification.evaluate` does.
    nominal : also the figures of the nominal robot (before compensation).

    Raises
    ------
    DataError
        Sensor data, an unknown or missing point label, a point and cycle given twice,
        a point with fewer than two cycles.
    """
    if meas.kind not in ("point", "pose"):
        raise DataError(
            f"{meas.source}: ISO 9283 figures need the tool's position (point or pose "
            f"data: x_mm, y_mm, z_mm); got {meas.kind} data."
        )
    idx, cyc = _check_labels(meas, point, cycle)
    cal = evaluate(calibrated, meas, refit=tuple(refit)).calibrated
    m = cal.align(meas)
    to_base = _to_base(cal, m.set_index)
    fig = _figures("model", cal, m, to_base, idx, cyc)
    _check_layout(meas.source, fig)
    nom = None
    if nominal:
        nom = _figures("nominal", nominal_placed(cal), m, to_base, idx, cyc)
    counts = {lab: int(np.sum(idx == k)) for k, lab in enumerate(POINT_LABELS)}
    notes = []
    if min(counts.values()) < DEFAULT_CYCLES:
        notes.append(
            f"{min(counts.values())} cycles at the least-measured point; ISO 9283 asks "
            f"for {DEFAULT_CYCLES} (the 3 S terms of RP are less certain with fewer)."
        )
    if fig.distance is None:
        notes.append("distance accuracy: P2 and P4 share fewer than two cycles.")
    return IsoEvaluation(fig, nom, meas.kind, counts, tuple(refit), notes)
