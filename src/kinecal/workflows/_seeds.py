"""The program's joints of ``kinecal compensate``'s TARGETS (the seeds) against the
targets: seeds typed in radians under ``jK_deg`` columns."""

from __future__ import annotations

import numpy as np

from kinecal.errors import DataError
from kinecal.io import CompensationTargets
from kinecal.measurement import CalibratedModel

# A calibrated model whose median error on a data file exceeds this is not being
# evaluated on its robot (another robot's data, another frame or units): refused.
OTHER_ROBOT_MM = 50.0


def check_seed_units(
    cal: CalibratedModel,
    tg: CompensationTargets,
    set_index: np.ndarray,
    marker_index: np.ndarray,
    path: str,
) -> None:
    """Refuse seeds in radians under degree columns: every revolute value within
    +-2 pi and the model at the seeds far from the targets (median over 50 mm, as no
    calibrated robot is off). The file reader tells radians from degrees by the spread
    of 5 rows or more; a short TARGETS (one to four rows) was compensated from the
    radian poses, every joint moved by tens of degrees, with exit 0."""
    from kinecal.models import ModelInputs

    robot = cal.model.robot
    deg = [k for k, c in enumerate(tg.joint_columns) if c.endswith("_deg")]
    if not deg or np.degrees(np.abs(tg.q_seed[:, deg])).max() > 2 * np.pi + 1e-9:
        return
    inputs = ModelInputs.make(tg.q_seed, set_index=set_index, marker_index=marker_index)
    p = cal.model.evaluate(cal.params, inputs).p_user
    off = float(np.median(np.linalg.norm(p - tg.p, axis=1))) * 1e3
    if off > OTHER_ROBOT_MM:
        cols = f"{tg.joint_columns[deg[0]]}..{tg.joint_columns[deg[-1]]}"
        raise DataError(
            f"{path}: columns {cols}: every value is within ±{2 * np.pi:.2f}, and "
            f"{robot.name} at these joints is {off:.0f} mm from the targets (median): "
            "they look like radians; convert to degrees or name the columns jK_rad."
        )
