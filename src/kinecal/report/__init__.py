"""Reports: JSON summaries, text tables, figures (matplotlib, optional) and HTML reports."""

from kinecal.report._html import write_calibration_report, write_comparison_report
from kinecal.report._summary import (
    calibration_summary,
    comparison_table,
    format_table,
    parameter_table,
)

__all__ = [
    "calibration_summary",
    "comparison_table",
    "format_table",
    "parameter_table",
    "write_calibration_report",
    "write_comparison_report",
]
