"""The calibration vocabulary below the fitter: measurements, residuals, metrics,
diagnostics and the calibrated model.

The edge packages (io, report, compensation, simulation, planning, sensor, workflows,
cli) import these names from here, not from :mod:`kinecal.identification` (which
re-exports them unchanged). Nothing here imports the identification.

Each name loads its module on first use (:mod:`kinecal._lazy`).
"""

from typing import TYPE_CHECKING

from kinecal import _lazy

if TYPE_CHECKING:
    from kinecal.measurement._calibrated import STATUSES, CalibratedModel
    from kinecal.measurement._diagnostics import CODES, Diagnostic, Outlier, StageLog
    from kinecal.measurement._measurements import KINDS, Measurements
    from kinecal.measurement._metrics import Metrics, metrics_from_errors
    from kinecal.measurement._residuals import ResidualBlock, Weights, residuals

__all__ = [
    "CODES",
    "KINDS",
    "STATUSES",
    "CalibratedModel",
    "Diagnostic",
    "Measurements",
    "Metrics",
    "Outlier",
    "ResidualBlock",
    "StageLog",
    "Weights",
    "metrics_from_errors",
    "residuals",
]

__getattr__, __dir__ = _lazy.exports(
    __name__,
    {
        "_calibrated": ("STATUSES", "CalibratedModel"),
        "_diagnostics": ("CODES", "Diagnostic", "Outlier", "StageLog"),
        "_measurements": ("KINDS", "Measurements"),
        "_metrics": ("Metrics", "metrics_from_errors"),
        "_residuals": ("ResidualBlock", "Weights", "residuals"),
    },
)
