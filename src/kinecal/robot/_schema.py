"""Robot YAML files: strict validation, loading to SI, dumping back to mm/deg.

Schema (DESIGN §11, with the optional extensions marked *)::

    name: my-robot
    description: free text                         *
    convention: dh | mdh
    units: {length: mm | m, angle: deg | rad}
    joints:
      - {name: J1*, theta_offset, d, a, alpha, limits: [lo, hi], type: revolute | prismatic*,
         velocity*: deg/s or mm/s (the file's units per second), effort*: N m or N}
    coupling: [{joint: 3, from: 2, factor: 1}]      # theta = C q_ctrl
    frame0: {x, y, z, r, w, p}                     * frame 0 of the joint table in the
                                                      robot base (a URDF's base link)
    flange: {x, y, z, r, w, p}                     * physical flange in the last joint frame
    tool: {x, y, z, r, w, p}                        nominal tool in the flange frame
    gravity: [gx, gy, gz]                           base frame; only the direction is used
    payload_kg: 1.5                                * payload at the tool, if known
    rated_payload_kg: 12.5                         * the maker's rated payload
    self_weight: {shoulder: 2, elbow: 3, wrist_frame: 4} | null   * (Eq. 25-26)
    link_masses:                                   * general link self-weight (Eq. 25,
      - {frame: 2, mass_kg: 4.2, com: [x, y, z]}      N links): body of DH frame k, its
                                                      centre of mass in that frame
    priors: {joint_length: 1, joint_angle: 0.1, ntm: 0.03,        * prior std of the
             load_compliance: 1e-3, link_moment: 2000, link_ratio: 10}  identification
        (lengths and angles in the file's units, load_compliance in rad/m; null = none)

Frames use Eq. 8's ``Trans(x, y, z) Rz(r) Ry(w) Rx(p)``. Unknown keys are errors.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from kinecal.errors import ConfigError
from kinecal.geometry import euler_transform, transform_to_euler
from kinecal.robot._description import (
    JointSpec,
    LinkMass,
    RobotDescription,
    SelfWeightSpec,
)
from kinecal.robot._joint_rates import check_rate
from kinecal.robot._unit_slips import check_unit_slips
from kinecal.units import ANGLE_UNITS, LENGTH_UNITS

__all__ = ["dump_robot", "robot_from_dict"]

_TOP_KEYS = {
    "name",
    "description",
    "convention",
    "units",
    "joints",
    "coupling",
    "frame0",
    "flange",
    "tool",
    "gravity",
    "payload_kg",
    "rated_payload_kg",
    "self_weight",
    "link_masses",
    "priors",
}
_REQUIRED_TOP = ("name", "convention", "units", "joints")
# Longer DH lengths and offsets are typing errors (and break the numerics). Far below,
# a DH d of tens of metres is real: the common normal of nearly parallel axes.
_MAX_LENGTH_M = 1e4
MAX_LENGTH_M = _MAX_LENGTH_M  # (the URDF import's bound of a DH row)
_JOINT_KEYS = {
    "name",
    "theta_offset",
    "d",
    "a",
    "alpha",
    "limits",
    "type",
    "velocity",
    "effort",
}
_JOINT_REQUIRED = ("theta_offset", "d", "a", "alpha")
_FRAME_KEYS = ("x", "y", "z", "r", "w", "p")
_COUPLING_KEYS = {"joint", "from", "factor"}
_SELF_WEIGHT_KEYS = {"shoulder", "elbow", "wrist_frame"}
_LINK_MASS_KEYS = {"frame", "mass_kg", "com"}
# priors key -> (group, kind) of the identification and the unit kind in the file.
_PRIOR_KEYS = {
    "joint_length": (("joint", "length"), "length"),
    "joint_angle": (("joint", "angle"), "angle"),
    "ntm": (("ntm", "ntm"), "angle"),
    "load_compliance": (("load", "compliance"), "si"),
    "link_moment": (("link", "moment"), "length"),
    "link_ratio": (("link", "ratio"), "si"),
}


def _priors(
    data: Any, where: str, lu: float, au: float
) -> dict[tuple[str, str], float]:
    _check_keys(data, set(_PRIOR_KEYS), where)
    out = {}
    for key, value in data.items():
        (group_kind, unit) = _PRIOR_KEYS[key]
        if value is None:
            out[group_kind] = float("inf")
            continue
        v = _number(value, f"{where}.{key}")
        if not v > 0:
            raise _err(f"{where}.{key}", f"expected a positive std (or null); got {v}.")
        out[group_kind] = v * {"length": lu, "angle": au, "si": 1.0}[unit]
    return out


def _err(where: str, msg: str) -> ConfigError:
    return ConfigError(f"{where}: {msg}")


def _number(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise _err(where, f"expected a number; got {value!r}.")
    x = float(value)
    if not np.isfinite(x):
        raise _err(where, f"expected a finite number; got {value!r}.")
    return x


def _check_keys(
    d: Any, allowed: set[str], where: str, required: tuple[str, ...] = ()
) -> None:
    if not isinstance(d, Mapping):
        raise _err(where, f"expected a mapping; got {type(d).__name__}.")
    for k in d:
        if k not in allowed:
            raise _err(
                where, f"unknown key {k!r} (allowed: {', '.join(sorted(allowed))})."
            )
    for k in required:
        if k not in d:
            raise _err(where, f"missing key {k!r}.")


def _mass(data: Mapping[str, Any], key: str, source: str) -> float | None:
    """An optional positive mass [kg] (``payload_kg``, ``rated_payload_kg``)."""
    if data.get(key) is None:
        return None
    m = _number(data[key], f"{source}: {key}")
    if not 0 < m <= 1e4:  # the heaviest robots carry 2.3 t; beyond: g or lb for kg
        raise _err(
            f"{source}: {key}", f"expected a positive mass up to 10000 kg; got {m:g}."
        )
    return m


def _link_masses(data: Any, where: str, n: int, lu: float) -> tuple[LinkMass, ...]:
    """The ``link_masses`` list: one body per DH frame, mass >= 0, com in file units."""
    if not isinstance(data, list):
        raise _err(where, f"expected a list of {{frame, mass_kg, com}}; got {data!r}.")
    out = []
    seen: set[int] = set()
    for i, b in enumerate(data):
        w = f"{where}[{i}]"
        _check_keys(b, _LINK_MASS_KEYS, w, ("frame", "mass_kg", "com"))
        k = b["frame"]
        if not isinstance(k, int) or isinstance(k, bool) or not 1 <= k <= n:
            raise _err(f"{w}.frame", f"expected a DH frame 1..{n}; got {k!r}.")
        if k in seen:
            raise _err(
                f"{w}.frame", f"frame {k} is listed twice; expected one body each."
            )
        seen.add(k)
        m = _number(b["mass_kg"], f"{w}.mass_kg")
        if m < 0 or m > 1e4:
            raise _err(f"{w}.mass_kg", f"expected a mass 0..10000 kg; got {m:g}.")
        c = b["com"]
        if not isinstance(c, list) or len(c) != 3:
            raise _err(f"{w}.com", f"expected [x, y, z]; got {c!r}.")
        com = [_number(x, f"{w}.com[{j}]") * lu for j, x in enumerate(c)]
        if max(abs(x) for x in com) > 100.0:
            raise _err(
                f"{w}.com",
                f"{c} is not a plausible centre of mass (over 100 m from its frame); "
                "check units.length.",
            )
        out.append(LinkMass(k, m, (com[0], com[1], com[2])))
    return tuple(out)


def _frame(d: Any, where: str, lu: float, au: float) -> np.ndarray:
    _check_keys(d, set(_FRAME_KEYS), where)
    v = np.array([_number(d.get(k, 0.0), f"{where}.{k}") for k in _FRAME_KEYS])
    far = np.flatnonzero(np.abs(v[:3] * lu) > _MAX_LENGTH_M)
    if far.size:
        k = _FRAME_KEYS[int(far[0])]
        raise _err(
            f"{where}.{k}",
            f"{v[far[0]]:g} is not a plausible offset (over {_MAX_LENGTH_M:g} m).",
        )
    for k, x in zip("rwp", v[3:] * au):  # an Euler angle: at most 2 turns
        if abs(x) > 4 * np.pi + 1e-9:
            angle = "rad" if au == 1.0 else "deg"
            also = "; did you mean 'deg'?" if angle == "rad" else "."
            raise _err(
                f"{where}.{k}",
                f"{d[k]:g} {angle} is not a plausible angle (over 2 turns; units.angle "
                f"is {angle!r}){also}",
            )
    v[:3] *= lu
    v[3:] *= au
    return euler_transform(v)


def _frame0(d: Any, where: str, length: str, angle: str, au: float) -> np.ndarray:
    """``frame0`` (a robot base's mount, at most 100 m and 2 turns): unit slips named."""
    lu = LENGTH_UNITS[length]
    T = _frame(d, where, lu, au)
    for k in _FRAME_KEYS:
        v = abs(d.get(k, 0.0))
        if k in "xyz" and v * lu > 100.0:
            also = "; did you mean 'mm'?" if length == "m" else "."
            raise _err(
                f"{where}.{k}",
                f"{d[k]:g} {length} is not a plausible offset of a robot's frame 0 "
                f"from its base (over 100 m; units.length is {length!r}){also}",
            )
    return T


def _units(data: Mapping[str, Any], source: str) -> tuple[str, str, float, float]:
    """The file's length and angle units, and their SI factors."""
    units = data["units"]
    _check_keys(units, {"length", "angle"}, f"{source}: units", ("length", "angle"))
    if not isinstance(units["length"], str) or units["length"] not in LENGTH_UNITS:
        raise _err(
            f"{source}: units.length",
            f"expected one of {', '.join(LENGTH_UNITS)}; got {units['length']!r}.",
        )
    if not isinstance(units["angle"], str) or units["angle"] not in ANGLE_UNITS:
        raise _err(
            f"{source}: units.angle",
            f"expected one of {', '.join(ANGLE_UNITS)}; got {units['angle']!r}.",
        )
    lu, au = LENGTH_UNITS[units["length"]], ANGLE_UNITS[units["angle"]]
    return units["length"], units["angle"], lu, au


def _dh_values(
    jr: Mapping[str, Any], where: str, length: str, angle: str, lu: float
) -> dict[str, float]:
    """A joint's four DH numbers (file units), checked against the file's units."""
    vals = {k: _number(jr[k], f"{where}.{k}") for k in _JOINT_REQUIRED}
    if angle == "rad":
        for k in ("theta_offset", "alpha"):
            if abs(vals[k]) > 2 * np.pi + 1e-9:
                raise _err(
                    f"{where}.{k}",
                    f"{vals[k]} is not an angle in rad (units.angle is 'rad'); "
                    "did you mean 'deg'?",
                )
    for k in ("d", "a"):
        if length == "m" and abs(vals[k]) > 20.0:
            raise _err(
                f"{where}.{k}",
                f"{vals[k]} m is not a plausible link length (units.length is "
                "'m'); did you mean 'mm'?",
            )
        if abs(vals[k] * lu) > _MAX_LENGTH_M:
            raise _err(
                f"{where}.{k}",
                f"{vals[k]:g} {length} is not a plausible length (over "
                f"{_MAX_LENGTH_M:g} m); expected a robot's dimension.",
            )
    return vals


def _joint_limits(
    jr: Mapping[str, Any], where: str, scale: float
) -> tuple[float, float]:
    """A joint's ``limits`` [SI] (unlimited when absent)."""
    if "limits" not in jr:
        return (-np.inf, np.inf)
    lim = jr["limits"]
    if not isinstance(lim, list) or len(lim) != 2:
        raise _err(f"{where}.limits", f"expected [lo, hi]; got {lim!r}.")
    lo = _number(lim[0], f"{where}.limits[0]") * scale
    hi = _number(lim[1], f"{where}.limits[1]") * scale
    if not lo < hi:
        raise _err(f"{where}.limits", f"lower limit must be below upper; got {lim!r}.")
    prismatic = jr.get("type") == "prismatic"
    check_travel(lo, hi, prismatic, f"{where}.limits", f" (limits {lim!r})")
    return (lo, hi)


# A revolute joint's limits beyond 4 turns (real arms: 1.25 at most) are a unit
# mistake: degrees where radians are expected. A prismatic one's beyond 1 km.
MAX_TURNS = 4.0


def check_travel(lo: float, hi: float, prismatic: bool, where: str, what: str) -> None:
    """Refuse joint limits [SI] no joint of an arm has (see :data:`MAX_TURNS`)."""
    bound = _MAX_LENGTH_M / 10 if prismatic else MAX_TURNS * 2 * np.pi
    if max(abs(lo), abs(hi)) > bound:
        unit = "m" if prismatic else "rad"
        also = "" if prismatic else f" ({MAX_TURNS:g} turns; degrees given as radians?)"
        raise ConfigError(
            f"{where}: [{lo:.6g}, {hi:.6g}] {unit}{what}; expected limits within "
            f"+-{bound:.6g} {unit}{also}."
        )


def _joint(
    jr: Any, i: int, source: str, length: str, angle: str, lu: float, au: float
) -> JointSpec:
    """Joint ``i`` (0-based) of the ``joints`` list."""
    where = f"{source}: joints[{i}]"
    _check_keys(jr, _JOINT_KEYS, where, _JOINT_REQUIRED)
    kind = jr.get("type", "revolute")
    if kind not in ("revolute", "prismatic"):
        raise _err(
            f"{where}.type", f"expected 'revolute' or 'prismatic'; got {kind!r}."
        )
    vals = _dh_values(jr, where, length, angle, lu)
    lim_scale = lu if kind == "prismatic" else au
    rates: dict[str, float | None] = {"velocity": None, "effort": None}
    for key, scale in (("velocity", lim_scale), ("effort", 1.0)):
        if jr.get(key) is not None:
            v = _number(jr[key], f"{where}.{key}")
            rates[key] = check_rate(v, key, kind == "prismatic", scale, where)
    jname = jr.get("name", f"J{i + 1}")
    if not isinstance(jname, str) or not jname or not jname.isprintable():
        raise _err(
            f"{where}.name", f"expected a non-empty one-line string; got {jname!r}."
        )
    return JointSpec(
        name=jname,
        theta_offset=vals["theta_offset"] * au,
        d=vals["d"] * lu,
        a=vals["a"] * lu,
        alpha=vals["alpha"] * au,
        kind=kind,
        limits=_joint_limits(jr, where, lim_scale),
        velocity=rates["velocity"],
        effort=rates["effort"],
    )


# The largest coupling factor (a joint's angle per unit of another motor's, SI): gear
# couplings of real arms are 1 (FANUC J2/J3) or below; 1e30 was refused only as a
# "singular" coupling, naming no entry.
MAX_COUPLING = 100.0


def _coupling(data: Mapping[str, Any], source: str, n: int) -> np.ndarray:
    """The coupling matrix ``C`` (theta = C q_ctrl) of the ``coupling`` list."""
    C = np.eye(n)
    coupling = data.get("coupling") or []
    if not isinstance(coupling, list):
        raise _err(
            f"{source}: coupling",
            f"expected a list of {{joint, from, factor}}; got {coupling!r}.",
        )
    for k_c, c in enumerate(coupling):
        where = f"{source}: coupling[{k_c}]"
        _check_keys(c, _COUPLING_KEYS, where, ("joint", "from", "factor"))
        j = c["joint"]
        f = c["from"]
        for key, val in (("joint", j), ("from", f)):
            if not isinstance(val, int) or isinstance(val, bool) or not 1 <= val <= n:
                raise _err(
                    f"{where}.{key}", f"expected a joint number 1..{n}; got {val!r}."
                )
        if j == f:
            raise _err(where, "a joint cannot be coupled to itself.")
        factor = _number(c["factor"], f"{where}.factor")
        if not abs(factor) <= MAX_COUPLING:  # a joint turns with another's motor
            raise _err(
                f"{where}.factor",
                f"{factor:g}; expected a coupling factor within ±{MAX_COUPLING:g} "
                "(FANUC J2/J3: 1).",
            )
        C[j - 1, f - 1] += factor
    if coupling and not np.linalg.cond(C) < 1e8:
        raise _err(
            f"{source}: coupling",
            "the couplings make the kinematic angles depend on each other so that the "
            "controller angles cannot be recovered (singular theta = C q); expected "
            "each joint's angle from its own motor plus others.",
        )
    return C


def _gravity(data: Mapping[str, Any], source: str) -> np.ndarray:
    """The ``gravity`` vector [m/s^2] (its direction; 9.80665 m/s^2 long)."""
    if "gravity" not in data:
        return np.array([0.0, 0.0, -9.80665])
    g = data["gravity"]
    if not isinstance(g, list) or len(g) != 3:
        raise _err(f"{source}: gravity", f"expected [gx, gy, gz]; got {g!r}.")
    gravity = np.array([_number(x, f"{source}: gravity[{i}]") for i, x in enumerate(g)])
    if np.linalg.norm(gravity) == 0:
        raise _err(f"{source}: gravity", "must not be the zero vector.")
    return gravity / np.linalg.norm(gravity) * 9.80665


def _self_weight(data: Mapping[str, Any], source: str, n: int) -> SelfWeightSpec | None:
    """The lumped self-weight layout: the file's, the default for an arm of 5 or more
    joints without ``self_weight`` or ``link_masses``, or None."""
    if "self_weight" not in data and n >= 5 and not data.get("link_masses"):
        return SelfWeightSpec()
    if data.get("self_weight") is None:
        return None
    swr = data["self_weight"]
    _check_keys(swr, _SELF_WEIGHT_KEYS, f"{source}: self_weight")
    vals_sw = {}
    for key, default in (("shoulder", 2), ("elbow", 3), ("wrist_frame", 4)):
        v = swr.get(key, default)
        if not isinstance(v, int) or isinstance(v, bool) or not 1 <= v <= n:
            raise _err(f"{source}: self_weight.{key}", f"expected 1..{n}; got {v!r}.")
        vals_sw[key] = v
    if not vals_sw["shoulder"] < vals_sw["elbow"] <= vals_sw["wrist_frame"]:
        raise _err(f"{source}: self_weight", "need shoulder < elbow <= wrist_frame.")
    return SelfWeightSpec(**vals_sw)


def robot_from_dict(data: Any, source: str = "<dict>") -> RobotDescription:
    """Validate a parsed robot YAML document and convert it to a :class:`RobotDescription`.

    Raises
    ------
    ConfigError
        With a one-line message naming ``source`` and the offending key.
    """
    _check_keys(data, _TOP_KEYS, source, _REQUIRED_TOP)
    name = data["name"]
    if not isinstance(name, str) or not name or not name.isprintable():
        # (it is written into file headers, URDFs and reports: no line breaks,
        # control or text-direction characters)
        raise _err(
            f"{source}: name", f"expected a non-empty one-line string; got {name!r}."
        )
    conv = data["convention"]
    if conv not in ("dh", "mdh"):
        raise _err(f"{source}: convention", f"expected 'dh' or 'mdh'; got {conv!r}.")
    length, angle, lu, au = _units(data, source)
    joints_raw = data["joints"]
    if not isinstance(joints_raw, list) or len(joints_raw) < 2:
        raise _err(f"{source}: joints", "expected a list of at least 2 joints.")
    joints = [
        _joint(jr, i, source, length, angle, lu, au) for i, jr in enumerate(joints_raw)
    ]
    n = len(joints)
    names = [j.name for j in joints]
    if len(set(names)) != n:
        raise _err(f"{source}: joints", f"joint names must be unique; got {names}.")
    C = _coupling(data, source, n)
    T_base_0 = np.eye(4)
    if "frame0" in data:
        T_base_0 = _frame0(data["frame0"], f"{source}: frame0", length, angle, au)
    T_n_flange = (
        _frame(data["flange"], f"{source}: flange", lu, au)
        if "flange" in data
        else np.eye(4)
    )
    T_flange_tool = (
        _frame(data["tool"], f"{source}: tool", lu, au)
        if data.get("tool")
        else np.eye(4)
    )
    check_unit_slips(joints, (T_n_flange, T_flange_tool), source, length, angle)
    gravity = _gravity(data, source)
    payload, rated = (
        _mass(data, key, source) for key in ("payload_kg", "rated_payload_kg")
    )
    sw = _self_weight(data, source, n)
    link_masses = (
        _link_masses(data["link_masses"], f"{source}: link_masses", n, lu)
        if data.get("link_masses")
        else ()
    )
    priors = (
        _priors(data["priors"], f"{source}: priors", lu, au)
        if data.get("priors")
        else {}
    )
    desc = data.get("description", "")
    return RobotDescription(
        name=name,
        convention=conv,
        joints=tuple(joints),
        coupling=C,
        T_flange_tool=T_flange_tool,
        T_n_flange=T_n_flange,
        gravity=gravity,
        payload_kg=payload,
        self_weight=sw,
        rated_payload_kg=rated,
        source=source if not desc else f"{source} ({desc})",
        prior_sigma=priors,
        link_masses=link_masses,
        T_base_0=T_base_0,
    )


def _frame_dict(T: np.ndarray) -> dict[str, float]:
    v = transform_to_euler(T)
    v[:3] *= 1e3
    v[3:] = np.degrees(v[3:])
    return {k: float(np.round(x, 12)) for k, x in zip(_FRAME_KEYS, v)}


def dump_robot(robot: RobotDescription) -> dict[str, Any]:
    """The YAML document (mm, deg) of a description; ``robot_from_dict`` reads it back."""
    joints = []
    for j in robot.joints:
        lim_scale = 1e3 if j.kind == "prismatic" else 180.0 / np.pi
        row: dict[str, Any] = {
            "name": j.name,
            # 1e-9 mm / deg: far below any accuracy, keeps the file readable.
            "theta_offset": round(float(np.degrees(j.theta_offset)), 9),
            "d": round(j.d * 1e3, 9),
            "a": round(j.a * 1e3, 9),
            "alpha": round(float(np.degrees(j.alpha)), 9),
        }
        if np.all(np.isfinite(j.limits)):
            row["limits"] = [j.limits[0] * lim_scale, j.limits[1] * lim_scale]
        if j.kind != "revolute":
            row["type"] = j.kind
        if j.velocity is not None:  # 12 digits: a slow speed is not rounded to 0
            row["velocity"] = float(f"{j.velocity * lim_scale:.12g}")
        if j.effort is not None:
            row["effort"] = float(f"{j.effort:.12g}")
        joints.append(row)
    coupling = [
        {"joint": int(r + 1), "from": int(c + 1), "factor": float(robot.coupling[r, c])}
        for r in range(robot.n_joints)
        for c in range(robot.n_joints)
        if r != c and robot.coupling[r, c] != 0.0
    ]
    out: dict[str, Any] = {
        "name": robot.name,
        "convention": robot.convention,
        "units": {"length": "mm", "angle": "deg"},
        "joints": joints,
        "coupling": coupling,
        "frame0": {k: v + 0.0 for k, v in _frame_dict(robot.T_base_0).items()},
        "flange": _frame_dict(robot.T_n_flange),
        "tool": _frame_dict(robot.T_flange_tool),
        "gravity": [float(x) for x in robot.gravity],
        "self_weight": None
        if robot.self_weight is None
        else {
            "shoulder": robot.self_weight.shoulder,
            "elbow": robot.self_weight.elbow,
            "wrist_frame": robot.self_weight.wrist_frame,
        },
    }
    if np.array_equal(robot.T_base_0, np.eye(4)):
        del out["frame0"]  # (none: the document of a robot file as before)
    if robot.link_masses:
        out["link_masses"] = [
            {
                "frame": b.frame,
                "mass_kg": float(b.mass),
                "com": [round(float(x) * 1e3, 9) for x in b.com],
            }
            for b in robot.link_masses
        ]
    if robot.payload_kg is not None:
        out["payload_kg"] = robot.payload_kg
    if robot.rated_payload_kg is not None:
        out["rated_payload_kg"] = robot.rated_payload_kg
    if robot.prior_sigma:
        to_file = {"length": 1e3, "angle": 180.0 / np.pi, "si": 1.0}
        out["priors"] = {
            key: (
                None
                if not np.isfinite(robot.prior_sigma[gk])
                else float(robot.prior_sigma[gk] * to_file[unit])
            )
            for key, (gk, unit) in _PRIOR_KEYS.items()
            if gk in robot.prior_sigma
        }
    return out
