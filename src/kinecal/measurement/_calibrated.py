"""A calibrated model: model structure plus identified parameters, ready to predict."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np

from kinecal._record import MutableRecord
from kinecal.errors import DataError
from kinecal.measurement._measurements import Measurements
from kinecal.measurement._metrics import Metrics, metrics_from_errors
from kinecal.measurement._residuals import ResidualBlock, Weights, residuals
from kinecal.models import CalibrationModel
from kinecal.typing import Float

__all__ = ["STATUSES", "CalibratedModel"]

STATUSES = ("estimated", "unidentifiable", "fixed")


@dataclass(eq=False, repr=False)
class CalibratedModel(MutableRecord):
    """Model structure plus identified parameters.

    Attributes
    ----------
    model : CalibrationModel
    params : (P,) identified parameters (SI).
    std : (P,) standard deviations (SI); NaN where a parameter was not estimated.
    status : list of str, per parameter: 'estimated', 'unidentifiable' (fixed at its
        start value because the poses cannot determine it) or 'fixed' (held by choice).
    reference_payload_kg : payload defining the unit weight of lambda*, if known.
    info : free-form metadata kept in model files (metrics, data source, ...).
    """

    model: CalibrationModel
    params: Float
    std: Float
    status: list[str]
    reference_payload_kg: float | None = None
    info: dict[str, object] = field(default_factory=dict)

    def __post_init__(self) -> None:
        P = self.model.size
        self.params = np.asarray(self.params, dtype=np.float64).reshape(P)
        self.std = np.asarray(self.std, dtype=np.float64).reshape(P)
        if len(self.status) != P or any(s not in STATUSES for s in self.status):
            raise ValueError(f"status must list one of {STATUSES} per parameter.")

    @property
    def layout(self):
        return self.model.layout

    def value(self, name: str) -> float:
        """Parameter value by exact name (SI)."""
        return float(self.params[self.model.layout.index(name)])

    def align(self, meas: Measurements) -> Measurements:
        """Map the set and marker labels of ``meas`` onto this model's.

        A model with a single user frame (or marker) accepts the data of one label,
        any (the data is taken to come from the same set-up), except a marker named
        otherwise than the model's; several labels onto one frame are refused.
        Otherwise every label must be known.
        """
        spec = self.model.spec
        out: dict[str, object] = {}
        for attr_i, attr_l, own, what in (
            ("set_index", "set_labels", spec.sets, "set"),
            ("marker_index", "marker_labels", spec.markers, "marker"),
        ):
            labels = getattr(meas, attr_l)
            idx = getattr(meas, attr_i)
            if tuple(labels) == tuple(own):
                continue
            hint = " Use --refit user for a new set-up." if what == "set" else ""
            out[attr_i] = map_labels(labels, idx, own, what, meas.source, hint=hint)
            out[attr_l] = own
        if not out:
            return meas
        from dataclasses import replace

        return replace(meas, **out)  # type: ignore[arg-type]

    def predict(
        self, meas: Measurements, weights: Weights | None = None
    ) -> ResidualBlock:
        """Residuals (model minus reference) of ``meas`` under this calibration."""
        if meas.n_joints != self.model.n_joints:
            raise DataError(
                f"{meas.source} has {meas.n_joints} joints; the model's robot "
                f"{self.model.robot.name} has {self.model.n_joints}."
            )
        m = self.align(meas)
        w = weights or Weights.default(m)
        return residuals(
            self.model,
            self.params,
            m,
            w,
            inputs=m.model_inputs(self.reference_payload_kg),
        )

    def metrics(self, meas: Measurements) -> Metrics:
        """Accuracy metrics of ``meas`` under this calibration."""
        blk = self.predict(meas)
        return metrics_from_errors(blk.raw_position, blk.raw_rotation)


def label_list(labels: Iterable[str], what: str = "set") -> str:
    """Set or marker labels for a message, the default one (``''``: data without the
    column) said in words, never as ``''``."""
    return ", ".join(repr(x) if x else f"the default {what}" for x in labels)


def map_labels(
    labels: Sequence[str],
    index: np.ndarray,
    own: tuple[str, ...],
    what: str,
    where: str,
    *,
    noun: str = "data",
    hint: str = "",
) -> np.ndarray:
    """The model's index (into ``own``, its sets or markers: ``what``) of each row,
    whose label is ``labels[index]``. A model with a single user frame (or marker)
    takes the rows of one label, any (the same set-up), except a marker named otherwise
    than the model's; several labels onto one frame are refused. Otherwise every label
    must be the model's. ``where`` starts the messages, ``noun`` names the rows
    ('data', 'targets'), ``hint`` ends the message of a label the model lacks."""
    if len(own) == 1:
        used = [labels[i] for i in np.unique(index)]
        named = [lab for lab in used if lab and own[0] and lab != own[0]]
        if len(used) > 1 or (what == "marker" and named):
            # several set-ups (points on the tool) cannot share one frame; a marker
            # named otherwise than the model's is another point
            why = (
                "each marker is its own point on the tool"
                if what == "marker"
                else "each set is its own user frame"
            )
            named_own = f" ({own[0]!r})" if own[0] else ""
            raise DataError(
                f"{where}: {what}s {label_list(used, what)} in the {noun}, but the "
                f"model has one {what}{named_own}: {why}; expected {noun} of that one "
                f"{what} (or a model calibrated with these {what}s)."
            )
        return np.zeros(index.shape[0], np.intp)
    missing = [lab for lab in labels if lab not in own]
    if missing and not missing[0]:  # rows without the column: the default label
        raise DataError(
            f"{where}: no {what} column, but the model has {what}s "
            f"{label_list(own, what)}; expected a {what} column naming them.{hint}"
        )
    if missing:
        raise DataError(
            f"{where}: {what} {missing[0]!r} is not in the model (it has "
            f"{label_list(own, what)}).{hint}"
        )
    return np.array([own.index(lab) for lab in labels], np.intp)[index]
