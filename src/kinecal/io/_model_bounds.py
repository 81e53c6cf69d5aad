"""Physical bounds of a model file's values, and its cross-checks (issue 35).

A ``model.yaml`` is input like any other: a hand edit or a damaged file must not give a
model that runs. Every parameter is checked against the range a real robot can have
(its kind's bound) and, for the kinematic rows, against the robot the file embeds; the
derived block ``frames_mm_deg`` must agree with the parameters it is computed from; the
robot's fingerprint (``robot_sha256``) must match the robot section.

The bounds are wide (a calibration never comes near them): they catch typing errors and
damaged files, not unusual robots. Each message names the file, the key, the value and
the range expected.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from kinecal.errors import ConfigError
from kinecal.io._files import sha256
from kinecal.models import CalibrationModel
from kinecal.robot import RobotDescription, dump_robot

__all__ = [
    "MAX_PAYLOAD_KG",
    "RATED_FACTOR",
    "check_frames",
    "check_info",
    "check_payload",
    "check_result",
    "check_value",
    "compliance_bound",
    "document_fingerprint",
    "max_payload_kg",
    "payload_limit",
    "robot_fingerprint",
    "value_bound",
]

# (kind, group) -> (bound on |value| in file units, what it is). Geometry rows are
# also checked against the nominal robot (_MAX_ROW_*).
_MAX_MM = 1e6  # lengths beyond 1 km are typing errors (and break the numerics)
_MAX_FRAME_DEG = 720.0  # Euler angles of a frame: two turns at most
_MAX_ROW_DEG = 30.0  # a joint row's angle: within 30 deg of the robot's nominal one
_MAX_NTM_DEG = 10.0  # a transmission error amplitude (real ones: ~0.01 deg)
_MAX_COMPLIANCE = 0.1  # rad/m: 0.1 rad of deflection for 1 m of lever (real: ~1e-4)
_MAX_RATIO = 1e4  # a link's mass per unit payload mass
MAX_PAYLOAD_KG = 1e4  # a reference payload; and at most 10 x the robot's rated one
RATED_FACTOR = 10.0


def robot_fingerprint(robot: RobotDescription) -> str:
    """A short SHA-256 of the robot's description (its YAML document, canonical JSON):
    two files describe the same robot exactly when their fingerprints agree."""
    return document_fingerprint(dump_robot(robot))


def document_fingerprint(doc: Any) -> str:
    """:func:`robot_fingerprint` of a robot section as read from a file: the same
    value when the section is exactly what kinecal wrote (a length in mm read into
    metres and dumped again can change in its last bit, so a file is checked against
    its own text, not against the robot rebuilt from it)."""
    text = json.dumps(doc, sort_keys=True, separators=(",", ":"))
    return sha256(text.encode("utf-8")).hexdigest()[:16]


def _wrap_deg(x: float) -> float:
    return (x + 180.0) % 360.0 - 180.0


def _reach_mm(robot: RobotDescription) -> float:
    """Sum of the robot's link lengths and offsets [mm] (its reach, roughly)."""
    from kinecal.robot._unit_slips import arm_length_m

    return 1e3 * arm_length_m(robot.joints, (robot.T_n_flange, robot.T_flange_tool))


def check_value(model: CalibrationModel, i: int, v: float, where: str) -> None:
    """Raise ConfigError if parameter ``i`` of ``model`` with value ``v`` (file units)
    is beyond its physical range; ``where`` names the file and key."""
    ps = model.layout.specs[i]
    unit = ps.unit.file_unit
    bound, what = value_bound(model, i)
    if bound is not None and abs(v) > bound:
        raise ConfigError(
            f"{where}: {v:g} {unit}; expected {what} within {bound:g} {unit} (from "
            f"-{bound:g} to {bound:g} {unit}; a typing error or a damaged file?)."
        )
    if ps.group != "joint":
        return
    nominal = float(model.nominal[i] * ps.unit.to_file)
    if unit == "deg":
        dev = abs(_wrap_deg(v - nominal))
        if dev > _MAX_ROW_DEG:
            raise ConfigError(
                f"{where}: {v:g} deg is {dev:.3g} deg from the robot's nominal "
                f"{nominal:g} deg; expected {nominal - _MAX_ROW_DEG:g} to "
                f"{nominal + _MAX_ROW_DEG:g} deg (a calibration corrects by far less: "
                "a typing error, or a model of another robot?)."
            )
    elif unit == "mm":
        reach = _reach_mm(model.robot)
        lim = max(100.0, 0.5 * reach)
        if abs(nominal) >= 100.0:  # a link: changed by half its length at most
            lim = min(lim, 0.5 * abs(nominal))
        if abs(v - nominal) > lim:
            raise ConfigError(
                f"{where}: {v:g} mm is {abs(v - nominal):.4g} mm from the robot's "
                f"nominal {nominal:g} mm; expected {nominal - lim:g} to "
                f"{nominal + lim:g} mm (a calibration corrects by far less: a typing "
                "error, or a model of another robot?)."
            )


def value_bound(model: CalibrationModel, i: int) -> tuple[float | None, str]:
    """(the bound on |value| of parameter ``i`` in file units or None, what it is)."""
    ps = model.layout.specs[i]
    unit, kind = ps.unit.file_unit, ps.kind
    if unit == "mm":
        return _MAX_MM, "a length"
    if kind == "ntm":
        return _MAX_NTM_DEG, "a transmission error amplitude"
    if kind == "compliance":
        return compliance_bound(model.robot, ps.joint or 0), (
            "a joint compliance (rad per m of lever: at most 0.1 rad of deflection "
            "at the joint's largest gravity torque)"
        )
    if kind == "ratio":
        return _MAX_RATIO, "a link mass per unit payload mass"
    if unit == "deg":
        return _MAX_FRAME_DEG, "an angle of at most two turns"
    return None, ""


# The largest gravity deflection of a joint a model can hold [rad] (5.7 deg): the
# bound of its compliance is this over the largest torque the joint carries.
_MAX_DEFLECTION = 0.1
_LEVERS: dict[int, tuple[RobotDescription, np.ndarray]] = {}
_PRIMES = (2, 3, 5, 7, 11, 13, 17, 19, 23, 29, 31, 37, 41, 43, 47, 53, 59, 61, 67, 71)


def compliance_bound(robot: RobotDescription, joint: int) -> float:
    """The largest |lambda*| of joint ``joint`` (1-based) [rad/m]: 0.1 rad/m, or more
    for a joint that carries little gravity torque, up to a deflection of 0.1 rad at the
    largest torque it carries (a wrist whose tool lies on its axis: 0.2 mm of lever per
    unit payload weight, where a fit of 1.57 rad/m deflects it 0.02 deg)."""
    hit = _LEVERS.get(id(robot))
    if hit is None or hit[0] is not robot:
        from kinecal.robot._gravity import finite_limits, gravity_torques

        # 256 poses spread over the limits by an additive recurrence: a deterministic
        # low-discrepancy set (numpy.random would cost a command 13 ms to import)
        n = robot.n_joints
        lim = finite_limits(robot)
        roots = [_PRIMES[i % 20] + 0.5 * (i // 20) for i in range(n)]
        u = (np.arange(1, 257)[:, None] * (np.sqrt(roots) % 1.0)) % 1.0
        q = lim[:, 0] + u * (lim[:, 1] - lim[:, 0])
        hit = (robot, np.abs(gravity_torques(robot, q)).max(axis=0))
        _LEVERS.clear()  # one robot at a time (the one being read or written)
        _LEVERS[id(robot)] = hit
    if not 1 <= joint <= hit[1].size:
        return _MAX_COMPLIANCE
    lever = float(hit[1][joint - 1])
    return max(_MAX_COMPLIANCE, float(f"{_MAX_DEFLECTION / max(lever, 1e-6):.2g}"))


def max_payload_kg(robot: RobotDescription) -> float:
    """The largest payload kinecal takes for ``robot`` [kg]: 10 x its rated payload, or
    :data:`MAX_PAYLOAD_KG` for a robot without one (beyond: a unit mistake, g or lb)."""
    rated = robot.rated_payload_kg
    return MAX_PAYLOAD_KG if rated is None else RATED_FACTOR * rated


def payload_limit(robot: RobotDescription) -> tuple[float, str]:
    """:func:`max_payload_kg` and the words for a message that gives it: " (10 x the
    R kg rated payload)", or '' for a robot without a rating."""
    rated = robot.rated_payload_kg
    also = "" if rated is None else f" (10 x the {rated:g} kg rated payload)"
    return max_payload_kg(robot), also


def check_payload(payload: float, robot: RobotDescription, where: str) -> None:
    """The reference payload [kg]: positive, and at most :func:`max_payload_kg`."""
    rated = robot.rated_payload_kg
    hi = max_payload_kg(robot)
    if not 0 < payload <= hi:
        also = "" if rated is None else f" (10 x the robot's rated {rated:g} kg)"
        raise ConfigError(
            f"{where}: {payload:g} kg; expected a positive mass up to {hi:g} kg{also}, "
            "or null."
        )


def check_frames(doc: Any, derived: dict[str, Any], p: Path) -> None:
    """``frames_mm_deg`` of a file against the frames its parameters give
    (``derived``, as written): a file whose block was edited is refused, since the
    parameters are what every command uses."""
    if doc is None:
        return
    where = f"{p}: frames_mm_deg"
    if not isinstance(doc, dict):
        raise ConfigError(f"{where}: expected a mapping of frames; got {doc!r}.")
    if set(map(str, doc)) != set(derived):
        raise ConfigError(
            f"{where}: frames {sorted(map(str, doc))}; expected "
            f"{sorted(derived)} (the frames of the model's sets and markers)."
        )
    for key, want in derived.items():
        got = doc[key]
        if not isinstance(got, dict) or set(map(str, got)) != set(want):
            raise ConfigError(f"{where}.{key}: expected {{x, y, z, r, w, p}}.")
        for k, w in want.items():
            v = got[k]
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                raise ConfigError(f"{where}.{key}.{k}: expected a number; got {v!r}.")
            diff = abs(v - w) if k in "xyz" else abs(_wrap_deg(v - w))
            if not math.isfinite(v) or diff > 1e-6 * max(1.0, abs(w)):
                unit = "mm" if k in "xyz" else "deg"
                raise ConfigError(
                    f"{where}.{key}.{k}: {v!r} {unit}, but the parameters give {w:.9g} "
                    f"{unit}; frames_mm_deg is computed from the parameters (edit "
                    "the parameters, or delete the block)."
                )


_KINDS = ("point", "pose", "sensor")


def check_info(info: Any, robot: RobotDescription, cam_rotation: bool, p: Path) -> None:
    """The ``info`` block's fields kinecal reads back: ``kind`` (the data the model was
    calibrated on: it decides which data ``evaluate`` accepts), ``n``, and
    ``calibrated_joint_range`` (N pairs [lo, hi] in deg, mm for a prismatic joint: the
    extrapolation warnings of ``evaluate`` and ``compensate``). A damaged block would
    silence those checks or turn them into nonsense. Other keys are free."""
    if not info:
        return
    where = f"{p}: info"
    kind = info.get("kind")
    if kind is not None:
        if kind not in _KINDS:
            raise ConfigError(
                f"{where}.kind: {kind!r}; expected one of {', '.join(_KINDS)} (the data "
                "the model was calibrated on)."
            )
        if kind != "point" and not cam_rotation:
            raise ConfigError(
                f"{where}.kind: {kind!r}, but model.cam_rotation is false (a model of "
                f"{kind} data has the tool orientation); expected 'point'."
            )
    n = info.get("n")
    if n is not None and (isinstance(n, bool) or not isinstance(n, int) or n < 1):
        raise ConfigError(
            f"{where}.n: {n!r}; expected the number of poses, a positive integer."
        )
    if "calibrated_joint_range" in info:
        _check_range(
            info["calibrated_joint_range"], robot, f"{where}.calibrated_joint_range"
        )


def _check_range(rng: Any, robot: RobotDescription, where: str) -> None:
    n = robot.n_joints
    units = ["mm" if pr else "deg" for pr in robot.prismatic]
    if not isinstance(rng, list) or len(rng) != n:
        raise ConfigError(
            f"{where}: {str(rng)[:80]}; expected {n} pairs [lo, hi] (one per joint, "
            f"{', '.join(units)})."
        )
    for i, pair in enumerate(rng):
        ok = (
            isinstance(pair, list)
            and len(pair) == 2
            and all(
                isinstance(v, (int, float))
                and not isinstance(v, bool)
                and math.isfinite(v)
                for v in pair
            )
        )
        if not ok or not pair[0] <= pair[1]:
            raise ConfigError(
                f"{where}[{i}] ({robot.joint_names[i]}): {pair!r}; expected [lo, hi] "
                f"with finite lo <= hi [{units[i]}] (the joint's range in the "
                "calibration data)."
            )
        _check_in_limits(pair, robot, i, f"{where}[{i}] ({robot.joint_names[i]})")


def _check_in_limits(
    pair: list[float], robot: RobotDescription, i: int, w: str
) -> None:
    """A calibrated range reaches at most a turn (a stroke, and 100 mm, for a slide)
    beyond the joint's limits: what the data may hold with --allow-out-of-limits. One
    beyond (a range in another unit, a typing error) silenced or faked the warnings
    for poses outside the calibrated ranges."""
    lo, hi = robot.limits[i]
    if not (np.isfinite(lo) and np.isfinite(hi)):
        return
    pris = bool(robot.prismatic[i])
    f, unit = (1e3, "mm") if pris else (180.0 / np.pi, "deg")
    far = max(hi - lo, 0.1) * f if pris else 360.0
    if pair[0] < lo * f - far or pair[1] > hi * f + far:
        raise ConfigError(
            f"{w}: {pair!r} {unit}; expected a range within the joint's limits "
            f"[{lo * f:.6g}, {hi * f:.6g}] {unit} (at most "
            f"{'a stroke' if pris else 'a turn'} beyond them: the range of the "
            "calibration data)."
        )


def check_result(cal: Any, source: str) -> None:
    """Refuse a calibration result (a :class:`~kinecal.measurement.CalibratedModel`)
    whose parameters lie beyond the bounds a model file accepts (:func:`check_value`):
    the fit of data of another robot (or with a wrong robot file) ends there. Named
    after the data (``source``), not after the model file it would have become, which
    kinecal itself would then refuse to read."""
    from kinecal.errors import DataError

    model = cal.model
    ref = cal.reference_payload_kg
    if ref is not None:  # the data's payload_kg (their mean, or the one given)
        try:
            check_payload(float(ref), model.robot, f"{source}: payload_kg")
        except ConfigError as exc:
            raise DataError(
                f"{exc} (the calibration's reference payload, from the data)"
            ) from None
    values = np.asarray(cal.params, float) * model.layout.to_file
    for i, ps in enumerate(model.layout.specs):
        try:
            check_value(model, i, float(values[i]), f"parameter {ps.name}")
        except ConfigError as exc:
            raise DataError(
                f"{source}: the {model.spec.name} fit ends with {exc} Expected data "
                f"of {model.robot.name}: are these measurements of another robot, or "
                "is the robot file wrong?"
            ) from None
