"""The ISO 9283 test cube and its five test points (ISO 9283:1998, 6.2; docs/iso9283.md).

The cube has its edges parallel to the robot base frame. Its corners are numbered C1-C4
around the bottom face (counter-clockwise seen from above, C1 at the lowest x, y) and
C5-C8 above C1-C4. A test plane is one of the four diagonal planes
``C1-C2-C7-C8`` (the standard's first choice), ``C2-C3-C8-C5``, ``C3-C4-C5-C6``,
``C4-C1-C6-C7``: each holds a bottom edge and the opposite top edge.

.. math::
    P_1 = c, \\qquad P_{k+2} = C_k + 0.1\\,(C_{k'} - C_k)

with ``c`` the cube's centre and ``C_k, C_{k'}`` the ends of a diagonal of the test
plane: P2-P5 lie on the plane's diagonals at 10 % of the diagonal's length from the
corners (P2 by the plane's first corner, P3 the second, P4 the third, P5 the fourth).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kinecal.typing import ArrayLike, Float

__all__ = ["PLANES", "POINT_LABELS", "VISIT_ORDER", "IsoCube", "iso_cube"]

POINT_LABELS = ("P1", "P2", "P3", "P4", "P5")
# The standard's order of visits in each cycle: P1 -> P5 -> P4 -> P3 -> P2.
VISIT_ORDER = ("P1", "P5", "P4", "P3", "P2")
# Corner numbers (1-based) of each diagonal test plane, in the order of P2..P5.
PLANES: dict[str, tuple[int, int, int, int]] = {
    "C1-C2-C7-C8": (1, 2, 7, 8),
    "C2-C3-C8-C5": (2, 3, 8, 5),
    "C3-C4-C5-C6": (3, 4, 5, 6),
    "C4-C1-C6-C7": (4, 1, 6, 7),
}
# Unit-cube signs of C1..C8 about the centre.
_SIGNS = np.array(
    [
        [-1, -1, -1],
        [1, -1, -1],
        [1, 1, -1],
        [-1, 1, -1],
        [-1, -1, 1],
        [1, -1, 1],
        [1, 1, 1],
        [-1, 1, 1],
    ],
    dtype=np.float64,
)
FRACTION = 0.1  # P2..P5 at 10 % of the diagonal from the corners


@dataclass(frozen=True)
class IsoCube:
    """A test cube in the robot base frame.

    Attributes
    ----------
    centre : (3,) cube centre in the robot base frame [m].
    edge : edge length [m].
    plane : the diagonal test plane (a key of :data:`PLANES`).
    """

    centre: Float
    edge: float
    plane: str = "C1-C2-C7-C8"

    def __post_init__(self) -> None:
        c = np.asarray(self.centre, np.float64)
        if c.shape != (3,) or not np.all(np.isfinite(c)):
            raise ValueError(
                f"centre must be 3 finite numbers [m]; got {self.centre!r}."
            )
        if not (np.isfinite(self.edge) and self.edge > 0):
            raise ValueError(f"edge must be positive [m]; got {self.edge!r}.")
        if self.plane not in PLANES:
            raise ValueError(
                f"plane must be one of {', '.join(PLANES)}; got {self.plane!r}."
            )
        object.__setattr__(self, "centre", c)
        object.__setattr__(self, "edge", float(self.edge))

    @property
    def corners(self) -> Float:
        """(8, 3) corners C1..C8 in the robot base frame [m]."""
        return self.centre + 0.5 * self.edge * _SIGNS

    @property
    def plane_corners(self) -> Float:
        """(4, 3) the test plane's corners, in the order of P2..P5 [m]."""
        return self.corners[[k - 1 for k in PLANES[self.plane]]]

    @property
    def points(self) -> Float:
        """(5, 3) test points P1..P5 in the robot base frame [m]."""
        pc = self.plane_corners
        # the diagonal's other end: corners 1<->3 and 2<->4 of the plane
        opposite = pc[[2, 3, 0, 1]]
        p = pc + FRACTION * (opposite - pc)  # 10 % of the diagonal from the corner
        return np.vstack([self.centre, p])

    @property
    def diagonal(self) -> float:
        """Length of the test plane's diagonals [m] (sqrt(3) x edge)."""
        return float(np.sqrt(3.0) * self.edge)


def iso_cube(centre: ArrayLike, edge: float, plane: str = "C1-C2-C7-C8") -> IsoCube:
    """The test cube of edge ``edge`` [m] centred on ``centre`` (3,) [m, base frame]."""
    return IsoCube(np.asarray(centre, np.float64), float(edge), plane)
