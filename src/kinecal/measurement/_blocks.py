"""Large Jacobians by blocks of poses: their products without holding them whole.

The identification needs the whitened Jacobian ``J`` (N, c, P') of the residuals mostly
through products: the normal matrix ``Jᵀ W J`` and ``Jᵀ W r`` (the solver, the priors, the
uncertainty, the identifiability analysis), per-group parts of it (the variance
components) and per-row blocks (the leave-one-out errors). For a million poses of the full
model ``J`` takes 1.3 GB, and several of them were alive at once. :class:`BlockJacobian`
evaluates it instead by blocks of about :data:`BLOCK_ROWS` residual rows (a block's
Jacobian takes about 25 MB, below glibc's mmap threshold, so its memory is reused and
touches no fresh pages) and accumulates the products, so memory stays linear in N and
small: the residuals, the inputs and one block.

Products are summed over blocks in their order; they equal those of the whole Jacobian to
rounding (the sums associate differently). Data of at most ``BLOCK_ROWS`` rows keep the
whole Jacobian (:func:`~kinecal.identification.residuals`), with the numbers they always
had.
"""

from __future__ import annotations

import contextlib
import contextvars
from collections.abc import Callable, Iterator

import numpy as np

from kinecal.models import ModelInputs
from kinecal.typing import Float

__all__ = [
    "BLOCK_ROWS",
    "BlockJacobian",
    "Blocks",
    "block_inputs",
    "reporting",
    "span_product",
    "tick",
]

# Residual rows (poses x components) of one block: 60,000 rows of the full model's 55
# columns are 26 MB. Data of more rows are evaluated by blocks.
BLOCK_ROWS = 60_000

Blocks = Iterator[tuple[slice, Float]]
# evaluate(rows, inputs of the rows, jacobian, products, raw) -> (r, J or None, e_p, e_r);
# with raw, J is not whitened (its rows are to be scaled by row_scale)
RowsFn = Callable[
    [slice, ModelInputs, bool, bool, bool],
    tuple[Float, Float | None, Float, Float | None],
]
Progress = Callable[[int, int], None]

# Where passes over blocks report ``(rows done, rows)`` and other long loops a word:
# set by a calibration for its duration (:func:`reporting`).
_REPORT: contextvars.ContextVar[tuple[Progress, Callable[[str], None]] | None] = (
    contextvars.ContextVar("kinecal_block_progress", default=None)
)


@contextlib.contextmanager
def reporting(
    progress: Progress | None, beat: Callable[[str], None] | None = None
) -> Iterator[None]:
    """Passes over blocks of poses inside report to ``progress(rows_done, rows)``, other
    long loops to ``beat(what)``."""
    token = _REPORT.set(
        None if progress is None else (progress, beat or (lambda what: None))
    )
    try:
        yield
    finally:
        _REPORT.reset(token)


def tick(done: int, total: int) -> None:
    """Report ``done`` of ``total`` rows of a pass (where :func:`reporting` is on)."""
    report = _REPORT.get()
    if report is not None:
        report[0](done, total)


def beat(what: str) -> None:
    """Report progress of a long loop in words (where :func:`reporting` is on)."""
    report = _REPORT.get()
    if report is not None:
        report[1](what)


def block_inputs(inputs: ModelInputs, rows: int) -> list[tuple[slice, ModelInputs]]:
    """The inputs of consecutive blocks of ``rows`` poses (views; kept with ``inputs``,
    so each block's quantities of the poses alone are computed once)."""

    def make() -> list[tuple[slice, ModelInputs]]:
        N = inputs.n
        return [
            (slice(lo, min(lo + rows, N)), inputs.subset(slice(lo, min(lo + rows, N))))  # type: ignore[arg-type]
            for lo in range(0, N, rows)
        ]

    return inputs.derived(("blocks", rows), make)


def span_product(
    J: Float,
    r: Float,
    cols: slice | np.ndarray,
    row_weights: Float | None,
    row_scale: Float | None = None,
) -> tuple[Float, Float]:
    """``(Xᵀ X, Xᵀ r)`` of the columns ``cols`` of ``J`` (n, c, P'), rows weighted.

    ``J`` in the model's parameter-major layout gives one product of contiguous rows (a
    slice of columns is a view; an index array, a copy of those columns only).
    ``row_scale`` (n,) whitens the rows of a raw ``J`` on the way (not ``r``)."""
    X = J.transpose(2, 1, 0)[cols]  # (k, c, n), rows in (component, sample) order
    rt = r.T
    w = row_weights
    if row_scale is not None:
        w = row_scale if w is None else row_scale * w
    if w is not None:
        X = X * w
    if row_weights is not None:
        rt = rt * row_weights
    Xm = X.reshape(X.shape[0], -1)
    return Xm @ Xm.T, Xm @ rt.reshape(-1)


class BlockJacobian:
    """The whitened Jacobian of one evaluation of large data, by blocks on demand.

    Parameters
    ----------
    rows_fn : evaluates the residuals (and Jacobian) of a slice of the data.
    inputs : ModelInputs of all rows.
    N, c, n_cols, n_all : poses, components per pose, the model's parameters and its
        parameters with the link products.
    r : (N, c) whitened residuals (filled by :meth:`residual_blocks`).
    row_scale : (N,) whitening of each row, when it is one factor per pose (point and
        sensor data): the normal equations then take the model's raw Jacobian and whiten
        only the columns they use, on the way.

    Each block reports ``(rows done, rows)`` where :func:`reporting` is on.
    """

    def __init__(
        self,
        rows_fn: RowsFn,
        inputs: ModelInputs,
        c: int,
        n_cols: int,
        n_all: int,
        row_scale: Float | None = None,
    ) -> None:
        self._rows_fn = rows_fn
        self.n = inputs.n
        self.c = c
        self.n_cols = n_cols
        self.n_all = n_all
        self._blocks = block_inputs(inputs, max(1, BLOCK_ROWS // c))
        self.row_scale = row_scale
        self._memo: dict[tuple[object, ...], tuple[Float, Float]] = {}
        self.r: Float | None = None
        self.passes = 0  # Jacobian passes over the data so far

    def residual_blocks(
        self,
    ) -> Iterator[tuple[slice, Float, Float, Float | None]]:
        """``(rows, r, e_p, e_r)`` of every block (the forward kinematics only)."""
        for sl, inp in self._blocks:
            r, _, e_p, e_r = self._rows_fn(sl, inp, False, False, False)
            yield sl, r, e_p, e_r
            self._tick(sl)

    def blocks(self, products: bool = False, raw: bool = False) -> Blocks:
        """``(rows, J (n, c, P'))`` of every block, evaluated one after the other (the
        link product columns with ``products``; not whitened with ``raw``, which needs
        :attr:`row_scale`)."""
        self.passes += 1
        for sl, inp in self._blocks:
            _, J, _, _ = self._rows_fn(sl, inp, True, products, raw)
            assert J is not None
            yield sl, J
            self._tick(sl)

    def _tick(self, sl: slice) -> None:
        tick(int(sl.stop), self.n)

    def normal(
        self, cols: np.ndarray, scales: Float, row_weights: Float | None = None
    ) -> tuple[Float, Float]:
        """``(Jsᵀ Js, Jsᵀ r)`` of the columns ``cols`` in scaled units, rows weighted by
        ``row_weights`` (N,) (as :func:`~kinecal.identification.normal_equations`), by
        one pass over the blocks (the last few results are kept)."""
        cols = np.asarray(cols, dtype=np.intp)
        if cols.size == 0:
            return np.zeros((0, 0)), np.zeros(0)
        scales = np.asarray(scales, np.float64)
        if row_weights is not None and np.all(row_weights == 1.0):
            row_weights = None  # the same products (a weight of 1 is exact)
        key = (
            cols.tobytes(),
            scales.tobytes(),
            None if row_weights is None else hash(np.asarray(row_weights).tobytes()),
        )
        hit = self._memo.get(key)
        if hit is not None:
            return hit[0].copy(), hit[1].copy()
        lo, hi = int(cols.min()), int(cols.max()) + 1
        # The span of the columns (a view), or the columns alone where they are few
        # (the registration's frames among the joint rows): a copy, but a smaller product.
        take: slice | np.ndarray = slice(lo, hi) if 2 * cols.size > hi - lo else cols
        k = hi - lo if isinstance(take, slice) else cols.size
        A = np.zeros((k, k))
        g = np.zeros(k)
        assert self.r is not None
        raw = self.row_scale is not None
        for sl, J in self.blocks(products=hi > self.n_cols, raw=raw):
            Ab, gb = span_product(
                J,
                self.r[sl],
                take,
                None if row_weights is None else row_weights[sl],
                None if self.row_scale is None else self.row_scale[sl],
            )
            A += Ab
            g += gb
        sel = cols - lo if isinstance(take, slice) else np.arange(cols.size)
        out = A[np.ix_(sel, sel)] * np.outer(scales, scales), g[sel] * scales
        if len(self._memo) >= 4:
            self._memo.pop(next(iter(self._memo)))
        self._memo[key] = out
        return out[0].copy(), out[1].copy()
