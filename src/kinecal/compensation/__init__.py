"""Compensation: corrected joint targets from a calibrated model (DESIGN §10)."""

from kinecal.compensation._compensate import STATUS, CompensationResult, compensate

__all__ = ["STATUS", "CompensationResult", "compensate"]
