"""Joints of a URDF beside the chain's geometry: velocity and effort limits, ``mimic``
joints read as a coupling (FANUC J2/J3 as kinecal's ``--coupling mimic`` writes it) and
the coupling line of kinecal's own exports."""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET

import numpy as np

from kinecal.errors import ConfigError
from kinecal.robot._joint_rates import rate_or_none

__all__ = ["declared_coupling", "merge_mimics", "mimic_of", "rates_of"]


def declared_coupling(text: str, n: int, src: str) -> np.ndarray:
    """The coupling matrix of kinecal's line ``kinecal coupling (theta = C q_ctrl): J3 +=
    1.0 * J2; ...`` (its URDF joints take kinematic angles; the robot takes controller
    angles, as the data hold them)."""
    C = np.eye(n)
    for term in filter(None, (t.strip() for t in text.split(";"))):
        m = re.fullmatch(r"J(\d+) \+= (\S+) \* J(\d+)\.?", term)
        try:
            if m is None:
                raise ValueError(term)
            i, k, f = int(m.group(1)) - 1, int(m.group(3)) - 1, float(m.group(2))
        except ValueError:
            raise ConfigError(
                f"{src}: cannot read the coupling term {term!r} of the 'kinecal "
                "coupling' line; expected 'Ji += factor * Jk'."
            ) from None
        if not (0 <= i < n and 0 <= k < n and i != k and np.isfinite(f)):
            raise ConfigError(
                f"{src}: coupling term {term!r}: expected joints 1..{n}, two different "
                "ones, and a finite factor."
            )
        C[i, k] += f
    if abs(np.linalg.det(C)) < 1e-9:
        raise ConfigError(f"{src}: the declared joint coupling is singular.")
    return C


def rates_of(
    lim: ET.Element | None, prismatic: bool = False
) -> tuple[float | None, float | None]:
    """Velocity and effort of a ``<limit>`` (None where absent, not positive, not a
    number, or beyond any joint's, :func:`kinecal.robot._joint_rates.rate_or_none`:
    ROS-Industrial writes effort 0 for unknown, some files 1e30 for unlimited)."""
    out: list[float | None] = []
    for key in ("velocity", "effort"):
        try:
            v = float(lim.get(key, "nan")) if lim is not None else np.nan
        except ValueError:
            v = np.nan
        out.append(rate_or_none(v, key, prismatic))
    return out[0], out[1]


def mimic_of(el: ET.Element, where: str) -> tuple[str, float, float]:
    """(joint, multiplier, offset) of a ``<mimic>`` element."""
    name = el.get("joint", "")
    if not name:
        raise ConfigError(
            f'{where}: expected <mimic joint="NAME" .../>; no joint named.'
        )
    try:
        mult = float(el.get("multiplier", "1"))
        off = float(el.get("offset", "0"))
    except ValueError:
        raise ConfigError(
            f"{where}: expected numbers; got multiplier={el.get('multiplier')!r}, "
            f"offset={el.get('offset')!r}."
        ) from None
    if not (np.isfinite(mult) and np.isfinite(off)) or mult == 0.0:
        raise ConfigError(
            f"{where}: expected a finite non-zero multiplier and a finite offset; got "
            f"multiplier={mult:g}, offset={off:g}."
        )
    return name, mult, off


def merge_mimics(lines, specs, mimics, src):
    """Joints that mimic another become a coupling: a mimic joint on the axis line of a
    neighbouring independent joint adds ``multiplier * q_other`` (and its offset) to
    that joint's kinematic angle (``theta = C q_ctrl``, FANUC J2/J3 as kinecal's
    ``--coupling mimic`` writes it). Returns the lines and specs of the independent
    joints, C and the angle offsets (n,)."""
    keep = [i for i in range(len(lines)) if i not in mimics]
    index = {specs[i][0]: k for k, i in enumerate(keep)}
    n = len(keep)
    C = np.eye(n)
    offsets = np.zeros(n)
    for i, (other, mult, off) in sorted(mimics.items()):
        name, kind, _ = specs[i]
        if other not in index:
            what = (
                "a mimic joint itself"
                if other in {s[0] for s in specs}
                else ("not a movable joint of the chain")
            )
            raise ConfigError(
                f"{src}: joint {name!r} mimics {other!r}, which is {what}; expected the "
                "name of an independent joint of the chain."
            )
        if kind != "revolute":
            raise ConfigError(
                f"{src}: joint {name!r} is a {kind} mimic joint; kinecal couples "
                "revolute joints only."
            )
        p, u = lines[i]
        host = None
        for k in (i + 1, i - 1):  # the independent neighbour on the same line
            if k in mimics or not 0 <= k < len(lines) or specs[k][1] != "revolute":
                continue
            q_, w = lines[k]
            d = p - q_
            if abs(abs(u @ w) - 1.0) < 1e-9 and np.linalg.norm(d - (d @ w) * w) < 1e-7:
                host = k
                sign = float(np.sign(u @ w))
                break
        if host is None:
            raise ConfigError(
                f"{src}: mimic joint {name!r} turns about its own axis; kinecal reads a "
                "mimic joint on the axis of the joint before or after it (a coupling "
                "such as FANUC J2/J3), not a separate linkage."
            )
        r = keep.index(host)
        C[r, index[other]] += sign * mult
        offsets[r] += sign * off
    if abs(np.linalg.det(C)) < 1e-9:
        raise ConfigError(f"{src}: the mimic joints make the joint coupling singular.")
    return [lines[i] for i in keep], [specs[i] for i in keep], C, offsets
