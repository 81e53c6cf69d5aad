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

from kinecal.errors import DataError
from kinecal.typing import ArrayLike, Float

__all__ = ["ModelInputs"]

_T = TypeVar("_T")


@dataclass(frozen=True)
class ModelInputs:
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
        N = q.shape[0]
        si = (
            np.zeros(N, np.intp)
            if set_index is None
            else np.asarray(set_index, np.intp)
        )
        mi = (
            np.zeros(N, np.intp)
            if marker_index is None
            else np.asarray(marker_index, np.intp)
        )
        pc = (
            np.zeros((N, 3))
            if p_cam is None
            else np.asarray(p_cam, np.float64).reshape(N, 3)
        )
        ls = (
            np.ones(N)
            if load_scale is None
            else np.asarray(load_scale, np.float64).reshape(N)
        )
        if si.shape != (N,) or mi.shape != (N,):
            raise DataError("set_index and marker_index must have one entry per pose.")
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
