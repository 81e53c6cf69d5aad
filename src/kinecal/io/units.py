"""Unit conversions at the edges (re-exported from :mod:`kinecal.units`)."""

from kinecal.units import (
    ANGLE_UNITS,
    LENGTH_UNITS,
    deg_to_rad,
    m_to_mm,
    mm_to_m,
    rad_to_deg,
    to_si_angle,
    to_si_length,
)

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
