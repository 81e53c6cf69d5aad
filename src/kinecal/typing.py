"""Array type aliases used in signatures. Shapes are documented in the alias comment."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["ArrayLike", "Float", "Int", "Pose", "Rotation", "Vec3"]

Float = NDArray[np.float64]  # any shape, float64
Int = NDArray[np.intp]  # any shape, integer indices
Pose = NDArray[np.float64]  # (..., 4, 4) homogeneous transform T_a_b
Rotation = NDArray[np.float64]  # (..., 3, 3) rotation matrix R_a_b
Vec3 = NDArray[np.float64]  # (..., 3) point or vector, frame given by its name
