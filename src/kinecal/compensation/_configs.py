"""Controller configuration flags of 6-axis arms (issue 34): which of the joint solutions
of a Cartesian target a program means.

=========  ==================================================  =========================
format     flags                                                read as (this module)
=========  ==================================================  =========================
fanuc-ls   ``CONFIG : 'N U T, t1, t4, t6'``                     N: J5 < 0 (F: J5 >= 0);
                                                                U: elbow bent as at the
                                                                zero pose; T: wrist centre
                                                                in front of the J1 axis;
                                                                t: turns of J1, J4, J6
                                                                (0: -180 <= J < 180 deg)
krl        ``S`` (status), ``T`` (turn)                         S bit 0: wrist centre
                                                                behind the A1 axis
                                                                (overhead); bit 1: A3 past
                                                                the stretched arm; T bit
                                                                k: A(k+1) < 0
rapid      ``[cf1, cf4, cf6, cfx]``                             quadrants floor(J/90 deg)
                                                                of J1, J4, J6; cfx bit 0:
                                                                J5 < 0, bit 1: elbow bent
                                                                against the zero pose,
                                                                bit 2: wrist centre behind
=========  ==================================================  =========================

The meaning of the letters and bits is taken from the vendors' manuals as we read them
(KUKA: status and turn of the KSS expert programming manual; ABB: confdata of the RAPID
reference; FANUC: the position configuration of the operator's manual); a controller's own
reading decides, so the report names the joints each target was solved at. KRL S bit 2
(A5) is not compared: T bit 4 says the same.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from kinecal.compensation._cartesian import arm_features, stretch_sign
from kinecal.measurement import CalibratedModel
from kinecal.typing import Float

__all__ = ["config_accept", "encode_config"]

_HALF_PI = np.pi / 2


def _turn(x: Float) -> np.ndarray:
    return np.floor((x + np.pi) / (2 * np.pi)).astype(int)


def encode_config(
    cal: CalibratedModel, fmt: str, q_ctrl: Float, stretch: float | None = None
) -> list[tuple]:
    """The configuration flags of joint vectors (M, n) as a program writes them
    (``stretch``: :func:`stretch_sign`, computed when not given)."""
    q = np.atleast_2d(np.asarray(q_ctrl, np.float64))
    if q.shape[1] != 6:
        raise ValueError("configuration flags are defined for 6-axis arms.")
    f = arm_features(cal, q, stretch)
    out: list[tuple] = []
    for k in range(q.shape[0]):
        front, elbow, wneg = (
            bool(f["front"][k]),
            bool(f["elbow"][k]),
            bool(f["wrist_neg"][k]),
        )
        if fmt == "fanuc-ls":
            t = _turn(q[k, [0, 3, 5]])
            out.append(
                (
                    "N" if wneg else "F",
                    "U" if elbow else "D",
                    "T" if front else "B",
                    *map(int, t),
                )
            )
        elif fmt == "krl":
            s = int(not front) + 2 * int(f["past_stretch"][k]) + 4 * int(wneg)
            bits = sum(1 << j for j in range(6) if q[k, j] < 0)
            out.append((s, bits))
        elif fmt == "rapid":
            cf = np.floor(q[k, [0, 3, 5]] / _HALF_PI).astype(int)
            cfx = int(wneg) + 2 * int(not elbow) + 4 * int(not front)
            out.append((*map(int, cf), cfx))
        else:
            raise ValueError(f"no configuration flags for {fmt!r}.")
    return out


def _same(fmt: str, mine: tuple, written: tuple) -> bool:
    if fmt == "krl":  # S bit 2 (A5) is T bit 4 again
        return (mine[0] & 3) == (written[0] & 3) and mine[1] == written[1]
    return tuple(mine) == tuple(written)


def config_accept(
    cal: CalibratedModel, fmt: str, configs: list[tuple]
) -> Callable[[int, Float], np.ndarray]:
    """``accept(i, q) -> (M,) bool``: which joint vectors have target i's flags."""

    stretch = stretch_sign(cal)

    def accept(i: int, q: Float) -> np.ndarray:
        enc = encode_config(cal, fmt, q, stretch)
        return np.array([_same(fmt, e, configs[i]) for e in enc], bool)

    return accept


def same_config(
    cal: CalibratedModel, fmt: str, q_ctrl: Float, configs: list[tuple]
) -> np.ndarray:
    """(M,) bool: the joints' flags are the written ones."""
    enc = encode_config(cal, fmt, q_ctrl)
    return np.array([_same(fmt, e, c) for e, c in zip(enc, configs)], bool)
