"""Tracker points measured in a left-handed frame (one axis negated in the instrument's
export): no rigid user frame maps the robot's motion onto them, and the fit ends far
off, blamed on the robot. Their mirror image fits: say so.

See docs/conventions.md (frames are right-handed).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from kinecal.identification._calibrate import CalibrationResult
from kinecal.identification._init import closed_form_frames
from kinecal.measurement._measurements import Measurements

__all__ = ["MIRROR_MM", "mirrored_frame"]

# The nominal robot with fitted frames misses a right-handed data set by a few mm (its
# tolerances), a mirrored one by a good part of its reach: the test runs above this.
MIRROR_MM = 20.0
# ... and names a mirror when the mirror image fits this many times better.
_BETTER = 5.0


def mirrored_frame(result: CalibrationResult, meas: Measurements) -> str | None:
    """A sentence for point data that the nominal robot (frames fitted) misses by over
    :data:`MIRROR_MM` RMS and whose mirror image (y negated) it fits five times better:
    a left-handed measurement frame; None otherwise."""
    before = result.metrics_before.rms_mm
    if meas.kind != "point" or not before > MIRROR_MM:
        return None
    flipped = replace(meas, p=meas.p * np.array([1.0, -1.0, 1.0]))
    model, x, _ = closed_form_frames(
        result.calibrated.model, result.registered, flipped
    )
    p = model.evaluate(x, flipped.model_inputs()).p_user
    mirrored = float(np.sqrt(((p - flipped.p) ** 2).sum(axis=1).mean())) * 1e3
    if not mirrored * _BETTER < before:
        return None
    return (
        f"{meas.source}: the positions are a mirror image of the robot's motion: the "
        f"nominal robot with fitted frames misses them by {before:.1f} mm RMS, their "
        f"mirror image (one axis negated) by {mirrored:.1f} mm. Expected positions in "
        "a right-handed frame: is the instrument's frame left-handed, or one axis's "
        "sign flipped in the export?"
    )
