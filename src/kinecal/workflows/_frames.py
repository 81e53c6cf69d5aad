"""The frames a program's Cartesian targets name (issue 34; ``kinecal compensate``):
``--uframe``/``--utool`` values and the controller's files (a frames YAML with FANUC
position registers, KUKA ``$config.dat``, FANUC ``SYSFRAME.VA`` / ``POSREG.VA``), with
the plausibility every frame and target must meet (no farther than a robot cell)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from kinecal.errors import DataError

__all__ = [
    "FAR_FRAME",
    "FAR_TOOL",
    "far_from_origin",
    "how_far",
    "load_frames_file",
    "parse_frames",
    "program_frames",
    "unit_words",
]

_FRAME_NUMBERS = {"fanuc-ls": 6, "krl": 6, "rapid": 7, "urscript": 6}
_EULER = ("fanuc-ls", "krl")  # x, y, z [mm] then three angles [deg]
# The farthest a user frame or a taught target may lie from its origin, and a tool from
# the flange [m]: beyond them a value is in the wrong units or damaged (1e308 mm ended in
# an overflow inside the inverse kinematics).
FAR_FRAME, FAR_TOOL = 100.0, 5.0


def far_from_origin(T: np.ndarray, limit: float) -> bool:
    """Whether a pose is not finite or its origin lies beyond ``limit`` [m]."""
    if not np.isfinite(T).all() or np.abs(T[:3, 3]).max() > limit:
        return True  # (no norm of huge numbers: it would overflow)
    return bool(np.linalg.norm(T[:3, 3]) > limit)


def how_far(T: np.ndarray) -> str:
    """How far a pose's origin is, for a message (no overflow for 1e308)."""
    t = T[:3, 3]
    big = float(np.max(np.abs(t)))
    if not np.isfinite(big):
        return "at infinity (a value is not finite)"
    d = big * float(np.linalg.norm(t / big)) if big > 0 else 0.0  # no overflow
    return f"{d:.4g} m"


def unit_words(fmt: str) -> str:
    return "m (URScript)" if fmt == "urscript" else "mm"


def parse_frames(
    specs: tuple[str, ...], fmt: str, option: str
) -> dict[str, np.ndarray]:
    """``ID=x,y,z,a,b,c`` values (the program's own units and angles; RAPID
    ``x,y,z,q1,q2,q3,q4``) -> {id: pose (4, 4) [m]}."""
    from kinecal.io._cartesian_programs import point_pose

    out = {}
    k = _FRAME_NUMBERS[fmt]
    for spec in specs:
        key, sep, rest = spec.partition("=")
        try:
            vals = [float(v) for v in rest.split(",")] if sep else []
        except ValueError:
            vals = []
        if not key.strip() or len(vals) != k or not np.isfinite(vals).all():
            raise DataError(
                f"{option} {spec!r}: expected ID={','.join(['v'] * k)} ({k} finite "
                f"numbers in the {fmt} program's units)."
            )
        turned = [v for v in vals[3:] if abs(v) > 360.0] if fmt in _EULER else []
        if turned:  # (W = 900 was taken as 180: a typing error, not an angle)
            raise DataError(
                f"{option} {spec!r}: angle {turned[0]:g} deg; expected the "
                "three angles in degrees within +-360."
            )
        try:
            T = point_pose(fmt, tuple(vals))
        except DataError as exc:
            raise DataError(f"{option} {spec!r}: {exc}") from None
        tool = option.rsplit(" ", 1)[-1].lower().endswith("tool")  # not the path's
        limit = FAR_TOOL if tool else FAR_FRAME
        if far_from_origin(T, limit):
            raise DataError(
                f"{option} {spec!r}: its origin lies {how_far(T)} away;"
                f" expected {unit_words(fmt)} and a "
                f"{'tool' if limit == FAR_TOOL else 'frame'} within {limit:g} m."
            )
        out[key.strip()] = T
    return out


def _krl_config_frames(path: str, text: str) -> tuple[dict, dict]:
    """``BASE_DATA[n]={X .., .., C ..}`` and ``TOOL_DATA[n]=..`` of a KUKA
    ``$config.dat`` -> (uframes, utools)."""
    import re

    from kinecal.io._cartesian_programs import point_pose

    out: tuple[dict, dict] = ({}, {})
    num = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
    pat = r"\b(BASE|TOOL)_DATA\s*\[\s*(\d+)\s*\]\s*=\s*\{([^{}]*)\}"
    for m in re.finditer(pat, text, re.I):
        vals = []
        for key in "XYZABC":
            k = re.search(rf"(?<![\w$]){key}\s+({num})", m.group(3))
            if k is None:
                line = text.count("\n", 0, m.start()) + 1
                raise DataError(f"{path}: line {line}: {m.group(1)}_DATA[{m.group(2)}] "
                                f"has no {key}; expected X, Y, Z [mm], A, B, C [deg].")  # fmt: skip
            vals.append(float(k.group(1)))
        tool = m.group(1).upper() == "TOOL"
        try:
            T = point_pose("krl", tuple(vals))
        except DataError as exc:
            line = text.count("\n", 0, m.start()) + 1
            raise DataError(f"{path}: line {line}: {exc}") from None
        if far_from_origin(T, FAR_TOOL if tool else FAR_FRAME):
            line = text.count("\n", 0, m.start()) + 1
            raise DataError(f"{path}: line {line}: {m.group(1)}_DATA[{m.group(2)}] lies "
                            f"{how_far(T)} away; expected mm and a "
                            f"{'tool within 5' if tool else 'frame within 100'} m.")  # fmt: skip
        out[tool][m.group(2)] = T
    return out


def _read_text(path: str) -> str:
    try:
        return Path(path).read_bytes().decode("utf-8", errors="replace")
    except OSError as exc:
        raise DataError(
            f"{path}: cannot read the frames file ({exc.strerror})."
        ) from None


def _yaml_registers(path: str, group: Any) -> dict:
    """``posreg: {n: {config: 'N U T, 0, 0, 0', xyzwpr: [6 numbers]} | {joints: [..]}}``
    -> {n: Register}."""
    from kinecal.io._fanuc_va import Register

    if not isinstance(group, dict):
        raise DataError(f"{path}: posreg: expected n: {{xyzwpr: [..], config: '..'}} "
                        "or n: {joints: [..]} entries.")  # fmt: skip
    out = {}
    for n, entry in group.items():
        what = f"{path}: posreg {n}"
        ok = isinstance(n, int) and n > 0 and isinstance(entry, dict)
        keys = set(entry) if ok else set()
        cart = keys == {"xyzwpr", "config"}
        ok = ok and (cart or keys == {"joints"})
        vals: Any = entry.get("xyzwpr" if cart else "joints") if ok else None
        ok = ok and isinstance(vals, list) and len(vals) >= (6 if cart else 1)
        ok = ok and all(isinstance(v, (int, float)) and np.isfinite(v) for v in vals)
        if not ok or (
            cart and (len(vals) != 6 or not isinstance(entry["config"], str))
        ):
            raise DataError(
                f"{what}: expected a register number > 0 with {{xyzwpr: [x, y, z, w, "
                "p, r] (mm, deg), config: 'N U T, 0, 0, 0'}} or {joints: [j1, .., jn] "
                "(deg)}."
            )
        kind = "cartesian" if cart else "joint"
        cfg = entry["config"] if cart else ""
        out[n] = Register(n, "", kind, tuple(float(v) for v in vals), cfg, 0)
    return out


def load_frames_file(path: str, fmt: str) -> tuple[dict, dict, dict]:
    """A YAML file ``{uframe: {ID: [..]}, utool: {ID: [..]}, posreg: {n: ..}}``, for
    KRL the controller's ``$config.dat`` (``BASE_DATA[n]``, ``TOOL_DATA[n]``), for FANUC
    the controller's ``SYSFRAME.VA`` or ``POSREG.VA`` -> (uframes, utools, registers)."""
    from kinecal import _yaml as yaml

    if fmt == "krl" and Path(path).suffix.lower() == ".dat":
        return (*_krl_config_frames(path, _read_text(path)), {})
    if fmt == "fanuc-ls" and Path(path).suffix.lower() == ".va":
        from kinecal.io._fanuc_va import read_posreg, read_va_frames

        text = _read_text(path)
        if "$POSREG" in text.upper():
            return {}, {}, read_posreg(path, text)
        uf, ut = read_va_frames(path, text)
        va = [tuple(f"{i}=" + ",".join(repr(v) for v in vals) for i, vals in d.items())
              for d in (uf, ut)]  # fmt: skip
        return (parse_frames(va[0], fmt, f"{path}: $MNUFRAME"),
                parse_frames(va[1], fmt, f"{path}: $MNUTOOL"), {})  # fmt: skip
    from kinecal.robot._robot_file import read_text_file  # (names a byte not UTF-8)

    try:
        doc = yaml.load(read_text_file(Path(path), "a frames YAML")) or {}
    except (OSError, yaml.YAMLError) as exc:
        raise DataError(f"{path}: cannot read the frames file ({exc}).") from None
    if not isinstance(doc, dict) or set(doc) - {"uframe", "utool", "posreg"}:
        raise DataError(
            f"{path}: expected the keys uframe and utool (ID: [numbers]) and, for "
            "FANUC, posreg."
        )
    if "posreg" in doc and fmt != "fanuc-ls":
        raise DataError(f"{path}: posreg: position registers are for FANUC programs.")
    out = []
    for key in ("uframe", "utool"):
        group = doc.get(key) or {}
        if not isinstance(group, dict):
            raise DataError(f"{path}: {key}: expected ID: [numbers] entries.")
        specs: list[str] = []
        for ident, nums in group.items():
            if not isinstance(nums, list):
                raise DataError(f"{path}: {key} {ident}: expected a list of numbers.")
            specs.append(f"{ident}=" + ",".join(str(v) for v in nums))
        out.append(parse_frames(tuple(specs), fmt, f"{path}: {key}"))
    return out[0], out[1], _yaml_registers(path, doc.get("posreg") or {})


def program_frames(
    fmt: str, uframes: tuple[str, ...], utools: tuple[str, ...], paths: tuple[str, ...]
) -> tuple[dict, dict, dict]:
    """(uframes, utools, registers) of a program run: the --frames files in order,
    then --uframe/--utool over them."""
    uf: dict = {}
    ut: dict = {}
    regs: dict = {}
    for path in paths:
        a, b, c = load_frames_file(path, fmt)
        uf.update(a)
        ut.update(b)
        regs.update(c)
    uf.update(parse_frames(uframes, fmt, "--uframe"))
    ut.update(parse_frames(utools, fmt, "--utool"))
    return uf, ut, regs
