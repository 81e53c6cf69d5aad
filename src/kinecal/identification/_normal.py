"""The normal equations of the Levenberg-Marquardt solver (:mod:`._lm`): of a held
Jacobian, or those a Jacobian evaluated by blocks of poses gives.

The products of a held Jacobian in the model's memory are the compiled kernel's
(:func:`kinecal.models._kernel.gram`: 0.76-0.85x the time of BLAS's at 2000 poses x 50
parameters) where it serves, BLAS's otherwise; the two agree to rounding."""

from __future__ import annotations

import weakref
from typing import Protocol

import numpy as np

from kinecal.measurement._residuals import ResidualBlock
from kinecal.models import _kernel
from kinecal.typing import Float

__all__ = ["NormalSource", "block_normal", "normal_equations", "normal_of"]


class NormalSource(Protocol):
    """A Jacobian that gives its normal equations without being held
    (:class:`~kinecal.measurement._blocks.BlockJacobian`)."""

    def normal(
        self, cols: np.ndarray, scales: Float, row_weights: Float | None = None
    ) -> tuple[Float, Float]: ...


def normal_of(
    r: Float,
    J: Float | NormalSource,
    cols: np.ndarray,
    scales: Float,
    row_weights: Float | None = None,
) -> tuple[Float, Float]:
    """:func:`normal_equations` of a held Jacobian, or those a block-wise one gives."""
    if isinstance(J, np.ndarray):
        return _normal_equations(r, J, cols, scales, row_weights, keep=True)
    return J.normal(cols, scales, row_weights)


def block_normal(
    blk: ResidualBlock,
    cols: np.ndarray,
    scales: Float,
    row_weights: Float | None = None,
) -> tuple[Float, Float]:
    """:func:`normal_equations` of a residual block's Jacobian, held (the products of an
    earlier call at the same point serve) or by blocks (:meth:`ResidualBlock.normal`)."""
    if blk.J is not None:
        return _normal_equations(blk.r, blk.J, cols, scales, row_weights, keep=True)
    return blk.normal(cols, scales, row_weights)


def normal_equations(
    r: Float,
    J: Float,
    cols: np.ndarray,
    scales: Float,
    row_weights: Float | None = None,
) -> tuple[Float, Float]:
    """``(Jsᵀ Js, Jsᵀ r)`` for the columns ``cols`` of J in scaled units.

    ``Js = J[:, :, cols] · scales`` with the rows of sample i multiplied by
    ``row_weights[i]`` (the square roots of robust weights) when given.

    Parameters
    ----------
    r : (N, c) residual rows.
    J : (N, c, P') Jacobian, any memory layout. The model's own (a view of a
        parameter-major (P', c, N) array) gives one product of contiguous rows over the
        span of ``cols``, with no copy for unweighted rows.
    cols : (k,) column indices.
    scales : (k,) characteristic size of each selected column.
    row_weights : (N,), optional.

    The products are formed anew at every call (the fitter's own calls reuse those of
    a Jacobian it holds: :func:`normal_of`, :func:`block_normal`).
    """
    return _normal_equations(r, J, cols, scales, row_weights, keep=False)


def _normal_equations(
    r: Float,
    J: Float,
    cols: np.ndarray,
    scales: Float,
    row_weights: Float | None,
    keep: bool,
) -> tuple[Float, Float]:
    """:func:`normal_equations`; ``keep``: the products of an earlier call on the same
    Jacobian serve, and these are kept for the next (:func:`_span_products`)."""
    cols = np.asarray(cols, dtype=np.intp)
    if cols.size == 0:
        return np.zeros((0, 0)), np.zeros(0)
    lo, hi = int(cols.min()), int(cols.max()) + 1
    A, g = _span_products(r, J, lo, hi, row_weights, keep)
    sel = cols - lo
    outer = np.outer(scales, scales)
    if sel.size == A.shape[0] and (sel.size < 2 or bool((np.diff(sel) == 1).all())):
        return A * outer, g * scales  # every column of the span, in order
    return A[np.ix_(sel, sel)] * outer, g[sel] * scales


# The products of the last few held Jacobians (issue 36): the stages read the normal
# equations of one Jacobian several times (the solver at a stage's last point, the prior
# adaptation, the evidence, the uncertainty, the next stage's start there), each time
# the same product of ~0.5 ms at 2000 poses x 50 parameters. Kept by the identity of
# the arrays (a Jacobian is never written after its evaluation), as weak references,
# with a copy of the residuals and row weights (a few us to compare: an array written
# in place between two calls is not taken for the one before). Only the fitter's own
# calls keep them; the public :func:`normal_equations` forms them anew.
_KEEP = 8
_Kept = tuple[tuple[weakref.ref, ...], Float, Float | None, int, int, Float, Float]
_kept: list[_Kept] = []


def _span_products(
    r: Float, J: Float, lo: int, hi: int, row_weights: Float | None, keep: bool = True
) -> tuple[Float, Float]:
    """``(Xᵀ X, Xᵀ r)`` of the columns ``lo:hi`` of ``J`` (rows weighted), from the
    products of an earlier call on the same arrays where there is one (a span that
    holds this one serves: its block; ``keep``), else by the compiled kernel or
    BLAS."""
    arrays = (J, r) if row_weights is None else (J, r, row_weights)
    for refs, r0, w0, a, b, A0, g0 in reversed(_kept[:]) if keep else ():
        # (a copy of the list: another thread may add)
        if (
            a <= lo
            and hi <= b
            and len(refs) == len(arrays)
            and all(ref() is x for ref, x in zip(refs, arrays))
            and np.array_equal(r0, r)
            and (w0 is None or row_weights is None or np.array_equal(w0, row_weights))
        ):
            return A0[lo - a : hi - a, lo - a : hi - a], g0[lo - a : hi - a]
    lo0, hi0 = lo, hi
    if lo == 0 and J.shape[-1] - hi <= hi // 8:
        # The few columns beyond (the link products of a lifted stage's Jacobian) come
        # along: the next stage's lifted start reads them at the same point.
        hi = J.shape[-1]
    G = _kernel.gram(J, r, lo, hi, row_weights)
    if G is not None:  # the compiled products: one triangle, Xᵀ r its last column
        k = hi - lo
        U = G[:k, :k]
        A = U + U.T  # (G has zeros below its diagonal) and the diagonal once:
        A.ravel()[:: k + 1] = U.diagonal()
        g = G[:k, k]
    else:
        A, g = _products(r, J, lo, hi, row_weights)
    A.setflags(write=False)
    g.setflags(write=False)
    if keep:
        try:
            refs = tuple(weakref.ref(x) for x in arrays)
            w0 = None if row_weights is None else np.array(row_weights)
            entry = (refs, np.array(r), w0, lo, hi, A, g)
            _kept[:] = [*_kept[-(_KEEP - 1) :], entry]
        except TypeError:  # (an array type without weak references: not kept)
            pass
    return A[lo0 - lo : hi0 - lo, lo0 - lo : hi0 - lo], g[lo0 - lo : hi0 - lo]


def _products(
    r: Float, J: Float, lo: int, hi: int, row_weights: Float | None
) -> tuple[Float, Float]:
    """``(Xᵀ X, Xᵀ r)`` of the columns ``lo:hi`` by BLAS (numpy's matmul)."""
    X = J.transpose(2, 1, 0)[lo:hi]  # (span, c, N), rows in (component, sample) order
    rt = r.T
    if row_weights is not None:
        X = X * row_weights
        rt = rt * row_weights
    Xm = X.reshape(hi - lo, -1)
    return Xm @ Xm.T, Xm @ rt.reshape(-1)
