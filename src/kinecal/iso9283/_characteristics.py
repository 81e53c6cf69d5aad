"""ISO 9283 pose and distance characteristics from attained and command poses.

For one test point measured in ``n`` cycles (ISO 9283:1998, 7.2 and 7.4; docs/iso9283.md):

.. math::
    AP_P = \\sqrt{(\\bar x - x_c)^2 + (\\bar y - y_c)^2 + (\\bar z - z_c)^2}, \\quad
    AP_x = \\bar x - x_c, \\ldots

    RP_l = \\bar l + 3 S_l, \\quad l_j = \\lVert p_j - \\bar p \\rVert, \\quad
    S_l = \\sqrt{\\textstyle\\sum_j (l_j - \\bar l)^2 / (n - 1)}

    AP_a = \\bar a - a_c, \\quad RP_a = \\pm 3 S_a, \\quad
    S_a = \\sqrt{\\textstyle\\sum_j (a_j - \\bar a)^2 / (n - 1)} \\quad (b, c\\ \\text{alike})

and between two points 1, 2 attained in the same cycles:

.. math::
    AD_P = \\bar D - D_c, \\quad D_j = \\lVert p_{1j} - p_{2j} \\rVert, \\quad
    D_c = \\lVert p_{c1} - p_{c2} \\rVert, \\quad
    RD = \\pm 3 \\sqrt{\\textstyle\\sum_j (D_j - \\bar D)^2 / (n - 1)}

Symbols: ``p_j = (x_j, y_j, z_j)`` attained position of cycle ``j``, ``p_c`` the command
position, ``a, b, c`` the orientation angles about the x, y, z axes (kinecal's Euler
sequence ``R = Rz(c) Ry(b) Rx(a)``, Eq. 8). Everything here is SI (m, rad) and in one
frame, the robot base frame in kinecal's use (:func:`kinecal.iso9283.evaluate_iso9283`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from kinecal.errors import DataError
from kinecal.geometry import matrix_to_euler_zyx
from kinecal.typing import Float, Int

__all__ = [
    "DistanceFigures",
    "PointFigures",
    "distance_characteristics",
    "orientation_abc",
    "pose_characteristics",
]

MIN_CYCLES = 2  # a standard deviation needs two cycles


@dataclass(frozen=True)
class PointFigures:
    """Pose accuracy and repeatability of one test point (SI).

    Attributes
    ----------
    label : the point's name (P1 .. P5).
    n : number of cycles measured.
    command : (3,) command position [m].
    mean : (3,) barycentre of the attained positions [m].
    ap : positional pose accuracy AP_P [m].
    ap_xyz : (3,) AP_x, AP_y, AP_z [m].
    l_bar, s_l : mean and standard deviation of the distances to the barycentre [m].
    rp : positional pose repeatability RP_l = l_bar + 3 S_l [m].
    ap_abc : (3,) or None, orientation accuracy AP_a, AP_b, AP_c [rad] (pose data).
    rp_abc : (3,) or None, orientation repeatability RP_a, RP_b, RP_c = 3 S [rad]
        (the standard writes ±3 S).
    """

    label: str
    n: int
    command: Float
    mean: Float
    ap: float
    ap_xyz: Float
    l_bar: float
    s_l: float
    rp: float
    ap_abc: Float | None = None
    rp_abc: Float | None = None


@dataclass(frozen=True)
class DistanceFigures:
    """Distance accuracy and repeatability between two test points (SI).

    Attributes
    ----------
    pair : the two points' labels.
    n : number of cycles in which both were attained.
    command : command distance D_c [m].
    mean : mean attained distance D_bar [m].
    ad : distance accuracy AD_P = D_bar - D_c [m].
    ad_xyz : (3,) AD_x, AD_y, AD_z (on the absolute coordinate differences) [m].
    rd : distance repeatability RD = 3 S_D [m] (the standard writes ±).
    ad_abc : (3,) or None, orientation distance accuracy AD_a, AD_b, AD_c: the mean
        attained change of the orientation angles from the first point to the second
        minus the command change [rad] (pose data).
    rd_abc : (3,) or None, orientation distance repeatability RD_a,b,c = 3 S [rad].
    """

    pair: tuple[str, str]
    n: int
    command: float
    mean: float
    ad: float
    ad_xyz: Float
    rd: float
    ad_abc: Float | None = None
    rd_abc: Float | None = None


def orientation_abc(R: Float) -> Float:
    """Orientation angles ``[a, b, c]`` (..., 3) [rad] about x, y, z of rotations
    (..., 3, 3): ``R = Rz(c) Ry(b) Rx(a)`` (Eq. 8; b in [-pi/2, pi/2])."""
    return matrix_to_euler_zyx(R)[..., ::-1]


def _wrap(a: Float) -> Float:
    return (a + np.pi) % (2 * np.pi) - np.pi


def _check(
    p_attained: Float, p_command: Float, point_index: Int, labels: Sequence[str]
) -> tuple[Float, Float, Int]:
    p = np.asarray(p_attained, np.float64)
    pc = np.asarray(p_command, np.float64)
    idx = np.asarray(point_index)
    if p.ndim != 2 or p.shape[1] != 3 or pc.shape != p.shape:
        raise ValueError(
            "p_attained and p_command must both have shape (N, 3); got "
            f"{p.shape} and {pc.shape}."
        )
    if idx.shape != (p.shape[0],) or not np.issubdtype(idx.dtype, np.integer):
        raise ValueError(f"point_index must be (N,) = ({p.shape[0]},) integers.")
    if idx.size and (idx.min() < 0 or idx.max() >= len(labels)):
        raise ValueError(f"point_index must lie in 0..{len(labels) - 1}.")
    if not (np.all(np.isfinite(p)) and np.all(np.isfinite(pc))):
        raise ValueError("p_attained and p_command must be finite.")
    return p, pc, idx.astype(np.intp)


def pose_characteristics(
    p_attained: Float,
    p_command: Float,
    point_index: Int,
    labels: Sequence[str],
    *,
    R_attained: Float | None = None,
    R_command: Float | None = None,
) -> tuple[PointFigures, ...]:
    """AP and RP (ISO 9283 7.2) of every test point.

    Parameters
    ----------
    p_attained : (N, 3) attained positions, one row per cycle and point [m].
    p_command : (N, 3) command position of each row [m]; a point's command is the mean
        of its rows' (the same value in a standard test).
    point_index : (N,) int, the test point of each row (index into ``labels``).
    labels : names of the points (P1 .. P5).
    R_attained, R_command : (N, 3, 3), optional
        Attained and command orientations (pose data): adds AP_a,b,c and RP_a,b,c.

    Returns
    -------
    one :class:`PointFigures` per label, in the order of ``labels``.

    Raises
    ------
    DataError
        A label without rows, or with fewer than two cycles.
    """
    p, pc, idx = _check(p_attained, p_command, point_index, labels)
    counts = np.bincount(idx, minlength=len(labels))
    for k, lab in enumerate(labels):
        if counts[k] < MIN_CYCLES:
            raise DataError(
                f"test point {lab}: {counts[k]} cycle(s) measured; expected at least "
                f"{MIN_CYCLES} (ISO 9283 asks for 30) to compute its repeatability."
            )
    orient = R_attained is not None
    if orient != (R_command is not None):
        raise ValueError("give both R_attained and R_command, or neither.")
    if orient:
        d_abc = _wrap(
            orientation_abc(np.asarray(R_attained, np.float64))
            - orientation_abc(np.asarray(R_command, np.float64))
        )
    n = counts.astype(np.float64)
    sums = [np.bincount(idx, p[:, i], len(labels)) for i in range(3)]
    mean = np.stack(sums, 1) / n[:, None]  # barycentre x_bar, y_bar, z_bar
    sums = [np.bincount(idx, pc[:, i], len(labels)) for i in range(3)]
    cmd = np.stack(sums, 1) / n[:, None]
    ap_xyz = mean - cmd  # AP_x = x_bar - x_c, ...
    ap = np.linalg.norm(ap_xyz, axis=1)  # AP_P
    l_j = np.linalg.norm(p - mean[idx], axis=1)  # distance to the barycentre
    l_bar = np.bincount(idx, l_j, len(labels)) / n
    s_l = np.sqrt(np.bincount(idx, (l_j - l_bar[idx]) ** 2, len(labels)) / (n - 1))
    rp = l_bar + 3.0 * s_l  # RP_l
    out = []
    for k, lab in enumerate(labels):
        ap_abc = rp_abc = None
        if orient:
            dk = d_abc[idx == k]
            ap_abc = _wrap(dk.mean(axis=0))  # AP_a = a_bar - a_c, ...
            rp_abc = 3.0 * dk.std(axis=0, ddof=1)  # RP_a = ±3 S_a, ...
        out.append(
            PointFigures(
                str(lab),
                int(counts[k]),
                cmd[k],
                mean[k],
                float(ap[k]),
                ap_xyz[k],
                float(l_bar[k]),
                float(s_l[k]),
                float(rp[k]),
                ap_abc,
                rp_abc,
            )
        )
    return tuple(out)


def distance_characteristics(
    p_attained: Float,
    p_command: Float,
    point_index: Int,
    cycle: Int,
    labels: Sequence[str],
    pair: tuple[str, str] = ("P2", "P4"),
    *,
    R_attained: Float | None = None,
    R_command: Float | None = None,
) -> DistanceFigures | None:
    """AD and RD (ISO 9283 7.4) between the two points of ``pair``, over the cycles in
    which both were attained; None when fewer than two such cycles exist.

    Parameters
    ----------
    p_attained, p_command, point_index, labels : as :func:`pose_characteristics`.
    cycle : (N,) int, the cycle of each row (one row per point and cycle).
    pair : the two points (the standard's distance test: P2 and P4).
    R_attained, R_command : (N, 3, 3), optional
        Attained and command orientations (pose data): adds AD_a,b,c and RD_a,b,c.
    """
    p, pc, idx = _check(p_attained, p_command, point_index, labels)
    if (R_attained is None) != (R_command is None):
        raise ValueError("give both R_attained and R_command, or neither.")
    cyc = np.asarray(cycle)
    if cyc.shape != idx.shape:
        raise ValueError(f"cycle must have shape {idx.shape}; got {cyc.shape}.")
    if any(lab not in labels for lab in pair):
        return None
    k1, k2 = (list(labels).index(lab) for lab in pair)
    r1, r2 = np.flatnonzero(idx == k1), np.flatnonzero(idx == k2)
    both, i1, i2 = np.intersect1d(cyc[r1], cyc[r2], return_indices=True)
    if both.size < MIN_CYCLES:
        return None
    a, b = r1[i1], r2[i2]  # rows of the same cycle
    c1, c2 = pc[r1].mean(axis=0), pc[r2].mean(axis=0)
    d_j = np.linalg.norm(p[a] - p[b], axis=1)  # D_j
    d_c = float(np.linalg.norm(c1 - c2))  # D_c
    d_bar = float(d_j.mean())
    ad_xyz = np.abs(p[a] - p[b]).mean(axis=0) - np.abs(c1 - c2)  # AD_x, AD_y, AD_z
    rd = 3.0 * float(d_j.std(ddof=1))  # RD = ±3 S_D
    ad_abc = rd_abc = None
    if R_attained is not None and R_command is not None:
        abc = orientation_abc(np.asarray(R_attained, np.float64))
        abc_c = orientation_abc(np.asarray(R_command, np.float64))
        d_abc = _wrap(abc[a] - abc[b])  # D_aj = a_1j - a_2j, ...
        # D_ca = a_c1 - a_c2 from the points' mean command angles (equal in a test)
        c_abc = _wrap(_mean_angle(abc_c[r1]) - _mean_angle(abc_c[r2]))
        ad_abc = _wrap(_mean_angle(d_abc) - c_abc)  # AD_a = D_bar_a - D_ca
        dev = _wrap(d_abc - _mean_angle(d_abc))
        rd_abc = 3.0 * np.sqrt(np.sum(dev**2, axis=0) / (d_abc.shape[0] - 1))
    return DistanceFigures(
        (pair[0], pair[1]),
        int(both.size),
        d_c,
        d_bar,
        d_bar - d_c,
        ad_xyz,
        rd,
        ad_abc,
        rd_abc,
    )


def _mean_angle(a: Float) -> Float:
    """Mean of angles (N, 3) [rad] about their first value (no jump at ±pi)."""
    return a[0] + _wrap(a - a[0]).mean(axis=0)
