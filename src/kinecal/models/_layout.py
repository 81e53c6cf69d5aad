"""Parameter registry: exact names, kinds (units), characteristic scales, flat vector.

Every model parameter has an exact name (``"base.x"``, ``"joint3.a"``, ``"cam.r"``,
``"joint2.ka1"``, ``"joint2.lambda"``, ``"link.s1"``) bound to one index of the flat SI
vector. Parameters are never bound by substring, and no helper mutates a shared dict;
what a name says (group, joint, set or marker label, field) is in fields of its
:class:`ParamSpec`, which :meth:`ParameterLayout.select` queries.

Kinds fix the SI unit, the unit shown in files and reports, and the characteristic scale
used to scale the identification Jacobian (``docs/conventions.md``).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from kinecal._record import Record
from kinecal.errors import ModelError
from kinecal.typing import ArrayLike, Float

__all__ = ["KINDS", "ParamKind", "ParamSpec", "ParameterLayout"]


@dataclass(frozen=True, eq=False, repr=False)
class ParamKind(Record):
    """Unit bookkeeping of one kind of parameter.

    Attributes
    ----------
    si_unit, file_unit : str
    to_file : float
        Factor from SI to the file/report unit.
    scale : float
        Characteristic size in SI used to scale Jacobian columns.
    """

    si_unit: str
    file_unit: str
    to_file: float
    scale: float


KINDS: dict[str, ParamKind] = {
    "length": ParamKind("m", "mm", 1e3, 1e-3),
    "angle": ParamKind("rad", "deg", 180.0 / np.pi, 1e-3),
    # Fourier amplitudes of joint transmission errors (Eq. 16): ~1e-4 rad.
    "ntm": ParamKind("rad", "deg", 180.0 / np.pi, 1e-4),
    # Joint compliance per unit payload weight, lambda* = |F| lambda (Eq. 24) [rad/m].
    "compliance": ParamKind("rad/m", "rad/m", 1.0, 1e-4),
    # Link first moment per unit payload weight, s* = s / |F| (Eq. 26) [m].
    "moment": ParamKind("m", "mm", 1e3, 0.1),
    # Mass of a link per unit payload mass (general link model).
    "ratio": ParamKind("1", "1", 1.0, 1.0),
}


@dataclass(frozen=True, eq=False, repr=False)
class ParamSpec(Record):
    """One named parameter, with what its name says as fields of their own.

    The model builds every spec of its layout (:class:`~kinecal.models.CalibrationModel`);
    code that needs to know what a parameter is reads these fields (or
    :meth:`ParameterLayout.select`), never the parts of its name.

    Attributes
    ----------
    name : str
        Exact name, as in ``model.yaml``: ``"base.x"``, ``"cam@n.r"``, ``"joint3.a"``,
        ``"joint2.ka1"``, ``"joint2.lambda"``, ``"link.s1"``, ``"link3.mx"``.
    kind : str
        Key of :data:`KINDS` (the unit and the characteristic scale).
    group : str
        ``'base'`` (user frame of a set), ``'cam'`` (cam frame of a marker), ``'joint'``
        (a row of the chain, Eq. 10), ``'ntm'`` (Fourier coefficient, Eq. 16), ``'load'``
        (compliance lambda*, Eq. 24) or ``'link'`` (link self-weight, Eq. 25-26).
    joint : int or None
        1-based joint of a row, a Fourier series or a compliance; the body (DH frame
        number) of a general link term (``link3.mx``: 3); None for frames and the lumped
        link moments.
    label : str or None
        Set label of a user frame, marker label of a cam frame (``''`` for the default
        one); None for the other groups.
    field : str
        The term within its frame, row, series or body: ``'x'``, ``'r'``,
        ``'theta_offset'``, ``'beta'``, ``'ka1'``, ``'lambda'``, ``'s1'``, ``'mx'``.
    """

    name: str
    kind: str
    group: str
    joint: int | None = None
    label: str | None = None
    field: str = ""

    @property
    def unit(self) -> ParamKind:
        return KINDS[self.kind]


class _Any:
    """Marker of a :meth:`ParameterLayout.select` criterion not given."""

    def __repr__(self) -> str:
        return "ANY"


_ANY: Any = _Any()


class ParameterLayout:
    """Ordered, immutable list of named parameters mapped onto a flat vector.

    Parameters
    ----------
    specs : iterable of ParamSpec
        Names must be unique.
    """

    def __init__(self, specs: Iterable[ParamSpec]) -> None:
        self._specs = tuple(specs)
        self._index = {s.name: i for i, s in enumerate(self._specs)}
        if len(self._index) != len(self._specs):
            dup = [n for n, c in Counter(s.name for s in self._specs).items() if c > 1]
            raise ModelError(f"duplicate parameter names in layout: {dup}.")
        for s in self._specs:
            if s.kind not in KINDS:
                raise ModelError(f"parameter {s.name!r} has unknown kind {s.kind!r}.")
        # Formed once (the layout is immutable); each read gets its own copy. The
        # calibration reads them a few hundred times (issue 36).
        self._scales = np.array([s.unit.scale for s in self._specs])
        self._names = [s.name for s in self._specs]

    # ------------------------------------------------------------------ access
    @property
    def specs(self) -> tuple[ParamSpec, ...]:
        return self._specs

    @property
    def names(self) -> list[str]:
        return list(self._names)

    @property
    def size(self) -> int:
        return len(self._specs)

    def __len__(self) -> int:
        return len(self._specs)

    def __contains__(self, name: object) -> bool:
        return name in self._index

    def __eq__(self, other: object) -> bool:
        return isinstance(other, ParameterLayout) and self._specs == other._specs

    def __hash__(self) -> int:
        return hash(self._specs)

    def __repr__(self) -> str:
        return f"ParameterLayout({self.size} parameters)"

    def index(self, name: str) -> int:
        """Position of ``name`` in the flat vector."""
        try:
            return self._index[name]
        except KeyError:
            groups = sorted({s.group for s in self._specs})
            raise ModelError(
                f"unknown parameter {name!r}; this layout has groups {', '.join(groups)}."
            ) from None

    def indices(self, names: Iterable[str]) -> np.ndarray:
        return np.array([self.index(n) for n in names], dtype=np.intp)

    def group_indices(self, group: str) -> np.ndarray:
        """Indices of every parameter of ``group`` (e.g. ``'base'``, ``'ntm'``)."""
        return np.array(
            [i for i, s in enumerate(self._specs) if s.group == group], dtype=np.intp
        )

    def select(
        self,
        *,
        group: str | Iterable[str] = _ANY,
        joint: int | None = _ANY,
        field: str | Iterable[str] = _ANY,
        label: str | None = _ANY,
    ) -> np.ndarray:
        """Indices (in layout order) of the parameters matching every criterion given.

        ``group`` and ``field`` take one value or several (any of them matches);
        ``joint`` and ``label`` one value, None included (``label=None``: parameters
        without a label, i.e. not of a frame). Example: the user-frame rotations of
        set ``'b'``, ``select(group='base', label='b', field=('r', 'w', 'p'))``.
        """
        groups, fields = _one_or_more(group), _one_or_more(field)
        return np.array(
            [
                i
                for i, s in enumerate(self._specs)
                if (groups is None or s.group in groups)
                and (joint is _ANY or s.joint == joint)
                and (fields is None or s.field in fields)
                and (label is _ANY or s.label == label)
            ],
            dtype=np.intp,
        )

    @property
    def groups(self) -> list[str]:
        out: list[str] = []
        for s in self._specs:
            if s.group not in out:
                out.append(s.group)
        return out

    @property
    def scales(self) -> Float:
        """Characteristic SI size of each parameter, shape (n,)."""
        return self._scales.copy()

    @property
    def to_file(self) -> Float:
        """Factor from SI to file units for each parameter, shape (n,)."""
        return np.array([s.unit.to_file for s in self._specs])

    @property
    def file_units(self) -> list[str]:
        return [s.unit.file_unit for s in self._specs]

    # ------------------------------------------------------------------ packing
    def pack(self, values: Mapping[str, float], base: ArrayLike | None = None) -> Float:
        """Flat SI vector from ``{name: value}``; names not given take ``base`` (or 0)."""
        out = np.zeros(self.size) if base is None else np.array(base, dtype=np.float64)
        if out.shape != (self.size,):
            raise ModelError(
                f"base vector must have shape ({self.size},); got {out.shape}."
            )
        for k, v in values.items():
            out[self.index(k)] = float(v)
        return out

    def unpack(self, vector: ArrayLike) -> dict[str, float]:
        """``{name: value}`` from a flat SI vector of shape (n,)."""
        v = np.asarray(vector, dtype=np.float64)
        if v.shape != (self.size,):
            raise ModelError(
                f"parameter vector must have shape ({self.size},); got {v.shape}."
            )
        return {s.name: float(x) for s, x in zip(self._specs, v)}

    def transfer(self, vector: ArrayLike, source: ParameterLayout) -> Float:
        """Values of ``vector`` (laid out as ``source``) copied into this layout by name.

        Parameters this layout has and ``source`` lacks are 0; extra ones are dropped.
        """
        v = np.asarray(vector, dtype=np.float64)
        out = np.zeros(self.size)
        for i, s in enumerate(self._specs):
            if s.name in source:
                out[i] = v[source.index(s.name)]
        return out


def _one_or_more(value: str | Iterable[str]) -> tuple[str, ...] | None:
    """A :meth:`ParameterLayout.select` criterion as a tuple (None: not given)."""
    if value is _ANY:
        return None
    return (value,) if isinstance(value, str) else tuple(value)
