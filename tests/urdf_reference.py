"""A minimal, independent URDF chain evaluator for the tests (scipy rotations only).

It shares no code with kinecal: it reads joint origins and axes from the XML and multiplies
``T_origin · Rot(axis, q)`` from the root link to the tip link.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation


def _origin(el: ET.Element | None) -> np.ndarray:
    T = np.eye(4)
    if el is None:
        return T
    xyz = [float(v) for v in el.get("xyz", "0 0 0").split()]
    rpy = [float(v) for v in el.get("rpy", "0 0 0").split()]
    T[:3, :3] = Rotation.from_euler(
        "xyz", rpy
    ).as_matrix()  # URDF: extrinsic roll, pitch, yaw
    T[:3, 3] = xyz
    return T


def urdf_chain_fk(path: Path, root: str, tip: str, q: np.ndarray) -> np.ndarray:
    """Pose of link ``tip`` in link ``root`` for joint values ``q`` (movable joints in order)."""
    tree = ET.parse(path).getroot()
    by_child = {j.find("child").get("link"): j for j in tree.findall("joint")}  # type: ignore[union-attr]
    chain = []
    link = tip
    while link != root:
        j = by_child[link]
        chain.append(j)
        link = j.find("parent").get("link")  # type: ignore[union-attr]
    chain.reverse()
    T = np.eye(4)
    k = 0
    for j in chain:
        T = T @ _origin(j.find("origin"))
        if j.get("type") in ("revolute", "continuous", "prismatic"):
            axis = np.array([float(v) for v in j.find("axis").get("xyz").split()])  # type: ignore[union-attr]
            M = np.eye(4)
            if j.get("type") == "prismatic":
                M[:3, 3] = axis * q[k]
            else:
                M[:3, :3] = Rotation.from_rotvec(axis * q[k]).as_matrix()
            T = T @ M
            k += 1
    return T
