"""Unit conversion at the edges: mm and degrees outside, SI (m, rad) inside.

This module has no dependencies so both the robot-file loader (core) and ``kinecal.io``
(edges) use it; it is the only place that knows the factors.
"""

from __future__ import annotations

import math

import numpy as np

from kinecal.typing import ArrayLike, Float

__all__ = [
    "ANGLE_UNITS",
    "LENGTH_UNITS",
    "deg_to_rad",
    "m_to_mm",
    "mm_to_m",
    "rad_to_deg",
    "to_si_angle",
    "to_si_length",
]

LENGTH_UNITS = {"mm": 1e-3, "m": 1.0}
ANGLE_UNITS = {"deg": math.pi / 180.0, "rad": 1.0}


def mm_to_m(x: ArrayLike) -> Float:
    return np.asarray(x, dtype=np.float64) * 1e-3


def m_to_mm(x: ArrayLike) -> Float:
    return np.asarray(x, dtype=np.float64) * 1e3


def deg_to_rad(x: ArrayLike) -> Float:
    return np.asarray(x, dtype=np.float64) * (math.pi / 180.0)


def rad_to_deg(x: ArrayLike) -> Float:
    return np.asarray(x, dtype=np.float64) * (180.0 / math.pi)


def to_si_length(x: ArrayLike, unit: str) -> Float:
    """Convert lengths given in ``unit`` ('mm' or 'm') to metres."""
    return np.asarray(x, dtype=np.float64) * LENGTH_UNITS[unit]


def to_si_angle(x: ArrayLike, unit: str) -> Float:
    """Convert angles given in ``unit`` ('deg' or 'rad') to radians."""
    return np.asarray(x, dtype=np.float64) * ANGLE_UNITS[unit]
