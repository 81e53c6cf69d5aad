"""Steps of ``export-urdf --like`` (:mod:`._urdf_like`): reading the vendor's file, the
joint motions and link transforms, placing the model's robot base in the vendor's root
frame, the new joint origins and the XML added for the calibrated tool and user links."""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

from kinecal.errors import ConfigError
from kinecal.geometry import matrix_to_rpy
from kinecal.robot._urdf_read import read_urdf
from kinecal.robot._urdf_tree import _floats, _plain
from kinecal.typing import Float, Pose

__all__ = [
    "axis_of",
    "check_link_names",
    "exact_link",
    "fixed_xml",
    "kabsch",
    "motion",
    "new_origins",
    "num",
    "place_base",
    "read_vendor",
    "with_comment",
]


def num(v: float) -> str:
    """17 significant digits; rounding noise below 1e-15 (m or rad) written as 0."""
    v = float(v)
    return repr(0.0 if abs(v) < 1e-15 else v + 0.0)


def axis_of(j: ET.Element, where: str) -> Float:
    el = j.find("axis")
    a = _floats(el.get("xyz") if el is not None else "1 0 0", 3, f"{where} axis")
    n = float(np.linalg.norm(a))
    if not n > 1e-9:
        raise ConfigError(f"{where} axis: expected a non-zero direction; got {a}.")
    return a / n


def motion(kind: str, axis: Float, v: float) -> Pose:
    M = np.eye(4)
    if kind == "prismatic":
        M[:3, 3] = v * axis
    else:
        K = np.array(
            [[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]]
        )
        M[:3, :3] = np.eye(3) + np.sin(v) * K + (1 - np.cos(v)) * K @ K
    return M


def exact_link(H: Pose, axis: Float, kind: str) -> Pose:
    """``H`` turned (by rounding-sized angles) so that the model's joint axis, seen from
    the vendor's link frame, is exactly the vendor's ``axis`` through its origin (the
    vendor's numbers such as 1.570796327 for pi/2 are otherwise a 1e-10 rad tilt)."""
    R = H[:3, :3]
    b = R.T @ np.array([0.0, 0.0, 1.0])
    c, d = np.cross(b, axis), float(b @ axis)
    K = np.array([[0, -c[2], c[1]], [c[2], 0, -c[0]], [-c[1], c[0], 0]])
    Q = np.eye(3) + K + K @ K / (1.0 + d)  # the rotation taking b to axis
    out = np.eye(4)
    out[:3, :3] = R @ Q.T
    out[:3, 3] = H[:3, 3] if kind == "prismatic" else [0.0, 0.0, H[2, 3]]
    return out


def kabsch(a: Float, b: Float) -> Float:
    """Rotation R minimising sum |R a_k - b_k|^2 (rows are vectors)."""
    U, _, Vt = np.linalg.svd(b.T @ a)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    return np.asarray(U @ D @ Vt)


def check_link_names(tool_link: str, user_link: str | None) -> None:
    """The names of the links export-urdf adds: URDF link names, not the same."""
    for what, given in (("--tool-link", tool_link), ("--user-link", user_link)):
        if given is not None and not re.fullmatch(
            r"[A-Za-z0-9_][A-Za-z0-9_.\-]*", given
        ):
            raise ConfigError(
                f"{what} {given!r}: expected a link name (letters, digits, '_', '-', '.')."
            )
    if tool_link == user_link:
        raise ConfigError(f"--tool-link and --user-link are both {tool_link!r}.")


def read_vendor(vendor: str | Path, text: str | None) -> tuple[str, ET.Element]:
    """(the text, its <robot> element without namespaces) of a plain URDF; the bytes
    decoded as they are (CRLF line ends and a byte order mark stay as they were)."""
    src = str(vendor)
    try:
        data = Path(vendor).read_bytes() if text is None else b""
        raw = data.decode("utf-8") if text is None else text
        if text is None:  # the checks every URDF reader makes (entities, xacro, size)
            read_urdf(vendor)
        root_el = ET.fromstring(raw.lstrip("\ufeff"))
    except UnicodeDecodeError as exc:  # UTF-16, Latin-1: written back as it was read
        line = data.count(b"\n", 0, exc.start) + 1
        raise ConfigError(
            f"{src}: line {line}: not UTF-8 text (byte 0x{data[exc.start]:02x}); "
            "expected a UTF-8 URDF for --like (its text is written back with the "
            "calibrated joints): save it as UTF-8."
        ) from None
    except (OSError, ET.ParseError) as exc:
        raise ConfigError(f"{src}: cannot read URDF ({exc}).") from exc
    if root_el.tag.rpartition("}")[2] != "robot":
        raise ConfigError(f"{src}: expected a <robot> document; got <{root_el.tag}>.")
    if any(
        "xacro" in (el.tag or "") for el in root_el.iter() if isinstance(el.tag, str)
    ):
        raise ConfigError(
            f"{src}: holds xacro elements; expected a plain URDF (expand it first: "
            "xacro FILE.xacro > FILE.urdf)."
        )
    return raw, _plain(root_el)


def place_base(
    J0: list[Pose], U0: list[Pose], dirs_v: Float, kinds: list[str], src: str
) -> tuple[Pose, float]:
    """(B, resid): the model's robot base in the vendor's root, from the joint axis
    lines of the zero pose (directions by Kabsch, the point by least squares across
    the revolute axes), and the largest distance of an axis from its counterpart."""
    dirs_m, dirs_u = _directions(J0, U0, dirs_v, kinds)
    if np.linalg.matrix_rank(dirs_m, tol=1e-6) < 2:
        raise ConfigError(
            f"{src}: all joint axes are parallel and the turning ones coincide; --like "
            "cannot place the robot base in the vendor's root frame (use export-urdf "
            "without --like)."
        )
    R = kabsch(dirs_m, dirs_u)
    rows, rhs = [], []
    for J, U, u, kind in zip(J0, U0, dirs_v, kinds):
        if kind == "prismatic":
            continue
        P = np.eye(3) - np.outer(u, u)
        rows.append(P)
        rhs.append(P @ (U[:3, 3] - R @ J[:3, 3]))
    t = np.linalg.lstsq(np.vstack(rows), np.concatenate(rhs), rcond=None)[0]
    B = np.eye(4)
    B[:3, :3], B[:3, 3] = R, t
    resid = 0.0
    for J, U, u, kind in zip(J0, U0, dirs_v, kinds):
        w = U[:3, 3] - (B @ J)[:3, 3]
        off = 0.0 if kind == "prismatic" else float(np.linalg.norm(w - (w @ u) * u))
        resid = max(resid, off, float(np.linalg.norm(R @ J[:3, 2] - u)))
    return B, resid


def _directions(
    J0: list[Pose], U0: list[Pose], dirs_v: Float, kinds: list[str]
) -> tuple[Float, Float]:
    """(model, vendor) directions that fix the base's rotation: the joint axes and,
    when these are all parallel (a SCARA), the common perpendiculars from the first
    turning axis to the others (a prismatic axis has a direction, not a line)."""
    dirs_m = np.array([J[:3, 2] for J in J0])
    if np.linalg.matrix_rank(dirs_m, tol=1e-6) >= 2:
        return dirs_m, dirs_v
    rev = [k for k, kind in enumerate(kinds) if kind != "prismatic"]
    extra_m: list[Float] = []
    extra_v: list[Float] = []
    for k in rev[1:]:
        for T, u, out in ((J0, dirs_m[0], extra_m), (U0, dirs_v[0], extra_v)):
            w = T[k][:3, 3] - T[rev[0]][:3, 3]
            out.append(w - (w @ u) * u)
    if not extra_m:
        return dirs_m, dirs_v
    return np.vstack([dirs_m, extra_m]), np.vstack([dirs_v, extra_v])


def new_origins(
    origins: list[Pose], U_cal: list[Pose], axes: dict
) -> tuple[list[Pose], float, float]:
    """(origins along the path with the movable joints' moved onto the calibrated
    frames ``U_cal``, largest move [m], largest turn [rad])."""
    new = list(origins)
    T = np.eye(4)
    i = 0
    for k in range(len(origins)):
        if k in axes:
            new[k] = np.linalg.inv(T) @ U_cal[i]
            T = U_cal[i]
            i += 1
        else:
            T = T @ origins[k]
    moved = max(float(np.linalg.norm(new[k][:3, 3] - origins[k][:3, 3])) for k in axes)
    cos = [(np.trace(new[k][:3, :3].T @ origins[k][:3, :3]) - 1) / 2 for k in axes]
    turned = max(float(np.arccos(np.clip(c, -1, 1))) for c in cos)
    return new, moved, turned


def fixed_xml(name: str, parent: str, child: str, O: Pose) -> list[str]:
    """A new link ``name`` and the fixed joint ``<name>_joint`` parent -> child."""
    return [
        f"  <link name={quoteattr(name)}/>\n",
        f'  <joint name={quoteattr(name + "_joint")} type="fixed">\n',
        f"    <parent link={quoteattr(parent)}/>\n",
        f"    <child link={quoteattr(child)}/>\n",
        f'    <origin xyz="{" ".join(num(v) for v in O[:3, 3])}" '
        f'rpy="{" ".join(num(v) for v in matrix_to_rpy(O[:3, :3]))}"/>\n',
        "  </joint>\n",
    ]


def with_comment(text: str, lines: list[str], eol: str = "\n") -> str:
    """``text`` with a comment of ``lines`` after the XML declaration (if any; after a
    byte order mark), its lines ended by ``eol``."""
    body = eol.join(f"  {ln}".rstrip().replace("--", "- -") for ln in lines)
    at = 1 if text.startswith("\ufeff") else 0
    m = re.compile(r"\s*<\?xml[^>]*\?>[ \t]*(\r?\n)?").match(text, at)
    if m:
        at = m.end()
    return text[:at] + f"<!--{eol}{body}{eol}-->{eol}" + text[at:]
