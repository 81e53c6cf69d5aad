"""A residual block at a point evaluated before, under other weights or without its
Jacobian: the same numbers as a new pass, without the pass (:class:`EvaluationCache`).

Whitening is ``r = e · (1/σ)`` row by row (:func:`kinecal.measurement._residuals.whiten`),
so residuals formed here from a block's raw errors are those a new evaluation at the same
point gives, to the last bit; a Jacobian's rows are rescaled by ``σ_was / σ``.
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING, Protocol

import numpy as np

from kinecal.measurement._residuals import ResidualBlock, Weights

if TYPE_CHECKING:
    from kinecal.models import CalibrationModel

__all__ = ["kept_errors", "nbytes", "raw_errors", "reweighted", "share_raw"]

Entry = tuple["CalibrationModel", bytes, Weights, ResidualBlock]


class EvaluationCache(Protocol):
    """What these helpers read of :class:`~._problem.EvaluationCache` (kept below it)."""

    _blocks: list[Entry]
    _raw: list[Entry]


# The model's forward state per pose (ForwardState: about 110 numbers).
_FORWARD_BYTES = 110 * 8


def _whitened(blk: ResidualBlock, w: Weights) -> np.ndarray:
    """The residuals of ``blk``'s raw errors under the weights ``w``."""
    inv_s = 1.0 / w.sigma
    if blk.raw_rotation is None:
        return blk.raw_position * inv_s[:, None]
    assert w.sigma_rot is not None
    inv_sr = 1.0 / w.sigma_rot
    return np.concatenate(
        [blk.raw_position * inv_s[:, None], blk.raw_rotation * inv_sr[:, None]], axis=1
    )


def reweighted(blk: ResidualBlock, was: Weights, w: Weights) -> ResidualBlock:
    """``blk`` (evaluated under the weights ``was``) whitened with ``w`` instead: the
    residuals from the raw errors, the Jacobian's rows rescaled (the same point, so no
    new Jacobian pass; the noise re-estimation changes only the weights)."""
    assert blk.J is not None
    r = _whitened(blk, w)
    ratio = was.sigma * (1.0 / w.sigma)
    if blk.raw_rotation is None:
        J = blk.J * ratio[:, None, None]
    else:
        assert w.sigma_rot is not None and was.sigma_rot is not None
        J = np.empty_like(blk.J)  # keeps the block's (parameter-major) layout
        np.multiply(blk.J[:, :3], ratio[:, None, None], out=J[:, :3])
        rr = was.sigma_rot * (1.0 / w.sigma_rot)
        np.multiply(blk.J[:, 3:], rr[:, None, None], out=J[:, 3:])
    return replace(blk, r=r, J=J)


def raw_errors(blk: ResidualBlock, was: Weights, w: Weights) -> ResidualBlock:
    """The residuals and raw errors of ``blk`` (evaluated under ``was``) under ``w``,
    without its Jacobian or the model's state (what a cache keeps of a point it no
    longer holds whole: 2 x 3 numbers a pose)."""
    r = blk.r if w is was else _whitened(blk, w)
    return ResidualBlock(r, None, blk.raw_position, blk.raw_rotation)


def nbytes(blk: ResidualBlock) -> int:
    """Memory a kept block holds (its arrays and the model's forward state)."""
    arrays = (blk.r, blk.J, blk.raw_position, blk.raw_rotation)
    held = sum(a.nbytes for a in arrays if a is not None)
    return held + (_FORWARD_BYTES * blk.r.shape[0] if blk.forward is not None else 0)


def kept_errors(
    ev: EvaluationCache, cm: CalibrationModel, x: np.ndarray, w: Weights
) -> ResidualBlock | None:
    """The residuals and raw errors at ``x`` under ``w`` from a block (or raw errors)
    the cache ``ev`` keeps at that point, whatever their weights; None where it keeps
    none (nothing is evaluated, nothing pushed out)."""
    key = np.asarray(x, np.float64).tobytes()
    for m, k, was, blk in reversed([*ev._raw, *ev._blocks]):
        if m is cm and k == key:
            return raw_errors(blk, was, w)
    return None


def share_raw(src: EvaluationCache, dst: EvaluationCache) -> None:
    """Let ``dst`` (a cache on the same rows) read the raw errors ``src`` keeps: a fit
    with other options from a point the calibration visited (the rejection's probe
    from the registered point) takes its errors there from them."""
    dst._raw = [*src._raw, *dst._raw]
