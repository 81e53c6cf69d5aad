"""Per-sample inputs of the calibration model (:class:`ModelInputs`).

The quantities that depend on the poses alone are computed once per inputs object and kept
with it (:meth:`ModelInputs.derived`); the model definition says which
(:meth:`~kinecal.models.ModelDefinition.coupled`,
:meth:`~kinecal.models.ModelDefinition.ntm_bases`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TypeVar, cast

import numpy as np

from kinecal._record import Record
from kinecal.errors import DataError
from kinecal.typing import ArrayLike, Float

__all__ = ["ModelInputs"]

_T = TypeVar("_T")


def _rows(
    name: str, value: ArrayLike | None, shape: tuple[int, ...], dtype: type, fill: float
) -> np.ndarray:
    """``value`` as an array of ``shape`` (``fill`` when None; the same number of
    entries in another layout is reshaped, as before); a mismatch names the argument
    and both shapes."""
    if value is None:
        return np.full(shape, fill, dtype=dtype)
    a = np.asarray(value)
    if a.size != int(np.prod(shape)):
        raise DataError(
            f"ModelInputs.make: {name} must have shape {shape} (one entry per pose of "
            f"q_ctrl, N = {shape[0]}); got shape {a.shape}."
        )
    if dtype is np.intp and a.size and not np.issubdtype(a.dtype, np.integer):
        if not (np.issubdtype(a.dtype, np.number) and np.all(a == np.round(a))):
            raise DataError(
                f"ModelInputs.make: {name} must hold integer indices; got {a.dtype}."
            )
    return np.asarray(a, dtype=dtype).reshape(shape)


@dataclass(frozen=True, eq=False, repr=False)
class ModelInputs(Record):
    """Per-sample inputs of the model (all SI).

    Attributes
    ----------
    q_ctrl : (N, n) controller joint values [rad, m].
    set_index : (N,) int, index into ``spec.sets`` (user frame per session).
    marker_index : (N,) int, index into ``spec.markers`` (cam frame per marker).
    p_cam : (N, 3) point in the cam frame [m] (zeros for a reflector at the cam origin).
    load_scale : (N,) payload of the row relative to the reference payload (1 by default).

    Quantities that depend on the poses alone (the coupled joint angles with their
    cosines and sines, the Fourier bases) are computed once per object and kept
    (:meth:`derived`), as every solver iteration evaluates the same poses. So that they
    cannot go stale, :meth:`make` and :meth:`subset` hold ``q_ctrl`` in a read-only copy;
    make new inputs for other joint values.
    """

    q_ctrl: Float
    set_index: np.ndarray
    marker_index: np.ndarray
    p_cam: Float
    load_scale: Float
    _derived: dict[tuple[object, ...], object] = field(
        default_factory=dict, init=False, repr=False, compare=False
    )

    @classmethod
    def make(
        cls,
        q_ctrl: ArrayLike,
        *,
        set_index: ArrayLike | None = None,
        marker_index: ArrayLike | None = None,
        p_cam: ArrayLike | None = None,
        load_scale: ArrayLike | None = None,
    ) -> ModelInputs:
        q = np.array(q_ctrl, dtype=np.float64, ndmin=2)  # its own copy, read-only below
        if q.ndim != 2:
            raise DataError(
                f"ModelInputs.make: q_ctrl must be (N, n) joint values; got shape "
                f"{q.shape}."
            )
        N = q.shape[0]
        si = _rows("set_index", set_index, (N,), np.intp, 0)
        mi = _rows("marker_index", marker_index, (N,), np.intp, 0)
        pc = _rows("p_cam", p_cam, (N, 3), np.float64, 0.0)
        ls = _rows("load_scale", load_scale, (N,), np.float64, 1.0)
        q.flags.writeable = False
        return cls(q, si, mi, pc, ls)

    @property
    def n(self) -> int:
        return int(self.q_ctrl.shape[0])

    def derived(self, key: tuple[object, ...], make: Callable[[], _T]) -> _T:
        """``make()``, computed on the first call with this ``key`` and kept; its arrays
        (an array or a tuple of them) are made read-only, as every caller shares them."""
        try:
            return cast(_T, self._derived[key])
        except KeyError:
            value = self._derived[key] = make()
            for a in value if isinstance(value, tuple) else (value,):
                if isinstance(a, np.ndarray):
                    a.flags.writeable = False
            return value

    def subset(self, rows: np.ndarray) -> ModelInputs:
        """The inputs of the selected rows (index or boolean mask)."""
        q = self.q_ctrl[rows]
        q.flags.writeable = False
        return ModelInputs(
            q,
            self.set_index[rows],
            self.marker_index[rows],
            self.p_cam[rows],
            self.load_scale[rows],
        )
