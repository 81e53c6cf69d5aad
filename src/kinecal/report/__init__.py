"""Reports: JSON summaries, text tables, SVG figures and self-contained HTML reports.

No matplotlib: the figures are SVG drawn by :mod:`kinecal.report._svg`. Each name loads
its module on first use (:mod:`kinecal._lazy`): a run without the HTML report (``kinecal
calibrate --no-report``) does not import the figures.
"""

from typing import TYPE_CHECKING

from kinecal import _lazy

if TYPE_CHECKING:
    from kinecal.report._calibration import (
        render_calibration_report,
        write_calibration_report,
        write_report,
    )
    from kinecal.report._html import write_comparison_report
    from kinecal.report._poses import (
        RESIDUALS_CSV,
        PoseErrors,
        pose_errors,
        read_pose_errors,
    )
    from kinecal.report._summary import (
        calibration_summary,
        comparison_table,
        format_table,
        parameter_table,
    )

__all__ = [
    "RESIDUALS_CSV",
    "PoseErrors",
    "calibration_summary",
    "comparison_table",
    "format_table",
    "parameter_table",
    "pose_errors",
    "read_pose_errors",
    "render_calibration_report",
    "write_calibration_report",
    "write_comparison_report",
    "write_report",
]

__getattr__, __dir__ = _lazy.exports(
    __name__,
    {
        "_calibration": (
            "render_calibration_report",
            "write_calibration_report",
            "write_report",
        ),
        "_html": ("write_comparison_report",),
        "_poses": ("RESIDUALS_CSV", "PoseErrors", "pose_errors", "read_pose_errors"),
        "_summary": (
            "calibration_summary",
            "comparison_table",
            "format_table",
            "parameter_table",
        ),
    },
)
