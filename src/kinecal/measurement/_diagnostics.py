"""What the identification found worth telling: structured diagnostics and stage logs.

Every finding of a stage is a :class:`Diagnostic` with a stable ``code`` (what tests and
programs match), the parameters or data rows it concerns, and a message for people. The
codes are listed in :data:`CODES`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from kinecal._record import MutableRecord, Record

__all__ = ["CODES", "Diagnostic", "Outlier", "StageLog"]

CODES: dict[str, str] = {
    "not_converged": "a stage stopped before convergence (parameters: where it drifts)",
    "targets_few": "a set sees fewer than three targets, or all on one line "
    "(parameters: the rotation of its user frame)",
    "frames_undetermined": "user and tool frame parameters the poses cannot separate",
    "priors_widened": "the data show larger deviations from nominal than the priors "
    "allowed (parameters: the single ones widened)",
    "no_covariance": "the normal matrix could not be inverted",
    "outliers": "rows whose error is improbable under the fitted noise (rows: file rows)",
    "prior_dominated": "parameters determined mostly by their prior",
    "loose_parameters": "parameters without a prior that the poses hardly determine",
    "overfit_risk": "many parameters for the number of residuals",
    "rotation_undetermined": "a registration could not fix a frame's rotation fully",
    "orientation_offset": "a session's orientations differ from the model's by a common "
    "rotation (a turned or re-mounted tool)",
    "rows_rejected": "rows rejected as gross errors and left out of the fit (rows: file "
    "lines)",
    "rejection_refused": "more than half the rows stand apart: none rejected",
    "systematic_residuals": "the largest residuals follow a joint angle or gravity load: "
    "a model error, not gross errors",
    "noise_model": "the noise (variance components) estimated from the residuals",
    # Checks of the data file before any fit (kinecal.io; stage 'data').
    "out_of_limits": "joint values beyond the robot's limits, accepted on request "
    "(rows: file lines)",
    "duplicate_rows": "rows that repeat an earlier row exactly (rows: file lines of the "
    "repeats)",
    "payload_over_rating": "a payload above the robot's rated payload (rows: file lines)",
    "quaternion_order": "orientations that fit the robot only when read in x, y, z, w "
    "order",
    "poor_excitation": "a joint that hardly moves, or a tool orientation that hardly "
    "changes: some parameters cannot be separated",
    "lone_label": "a marker or set seen in one row only: a calibration fits it to that "
    "row alone (rows: the file line)",
    "set_like_column": "a column named as set-ups (session, station, ...) with several "
    "values, where kinecal reads them from 'set' only: one user frame for all rows",
    "positions_only": "the data carry more than the model uses: only positions are "
    "compared",
    "extrapolation": "poses outside the joint ranges the model was calibrated on "
    "(rows: file lines; parameters: the joints)",
    # Checks of a calibration against its nominal robot (identification._nominal_check).
    "nominal_mismatch": "the nominal robot with fitted frames leaves errors far beyond "
    "the calibrated ones and parameters far from nominal: a wrong nominal table or units",
    "priors_held": "parameters the priors hold near nominal values the data clearly "
    "reject (parameters: those held)",
}


@dataclass(frozen=True, eq=False, repr=False)
class Diagnostic(Record):
    """One finding of a calibration stage.

    Attributes
    ----------
    code : str, one of :data:`CODES`.
    message : str, the finding in words (what the console and the report show).
    parameters : names of the parameters concerned (exact layout names).
    rows : data rows concerned (row numbers of the source file, 1-based data rows).
    stage : name of the stage that found it.
    severity : 'warning' (shown to the user) or 'info' (log and report only).
    """

    code: str
    message: str
    parameters: tuple[str, ...] = ()
    rows: tuple[int, ...] = ()
    stage: str = ""
    severity: str = "warning"

    def __post_init__(self) -> None:
        if self.code not in CODES:
            raise ValueError(f"unknown diagnostic code {self.code!r}; see CODES.")
        if self.severity not in ("warning", "info"):
            raise ValueError(
                f"severity must be 'warning' or 'info'; got {self.severity!r}."
            )

    def __str__(self) -> str:
        return self.message

    def as_dict(self) -> dict[str, Any]:
        return {
            "code": self.code,
            "severity": self.severity,
            "stage": self.stage,
            "message": self.message,
            "parameters": list(self.parameters),
            "rows": list(self.rows),
        }


@dataclass(eq=False, repr=False)
class StageLog(MutableRecord):
    """What one stage (one solver run) did."""

    name: str
    n_free: int
    rms_before_mm: float
    rms_after_mm: float
    iterations: int
    status: str
    success: bool
    seconds: float
    iteration_log: list[dict[str, float]] = field(default_factory=list)


@dataclass(frozen=True, eq=False, repr=False)
class Outlier(Record):
    """A row whose error is improbable under the fitted noise."""

    row: int
    error_mm: float
    z: float
