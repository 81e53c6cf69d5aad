"""The paper's fixed-step update (Sec. 4), kept only as a benchmark baseline."""

from __future__ import annotations

import numpy as np

from kinecal.identification._lm import ResidualFn
from kinecal.typing import Float

__all__ = ["solve_fixed_step"]


def solve_fixed_step(
    fun: ResidualFn,
    x0: Float,
    free: np.ndarray,
    *,
    zeta: float = 0.005,
    n_iter: int = 200,
) -> tuple[Float, list[float]]:
    """The paper's update ``eta_{k+1} = eta_k + zeta (J^T J)^-1 J^T dq`` (Sec. 4).

    A benchmark baseline only: with ``zeta = 0.005`` each iteration removes 0.5 % of the
    Gauss-Newton step, so it needs thousands of iterations to converge.

    Returns
    -------
    x : (P,) final parameters
    costs : list of ``|r|^2 / 2`` per iteration
    """
    x = np.array(x0, dtype=np.float64)
    fidx = np.flatnonzero(np.asarray(free, dtype=bool))
    costs = []
    for _ in range(n_iter):
        r, J = fun(x, True)
        assert isinstance(J, np.ndarray), "solve_fixed_step needs the Jacobian held"
        Jf = J[:, :, fidx].reshape(-1, fidx.size)
        rf = r.reshape(-1)
        costs.append(0.5 * float(rf @ rf))
        step = np.linalg.lstsq(Jf, -rf, rcond=None)[0]  # (J^T J)^-1 J^T dq, Eq. (28)
        x[fidx] += zeta * step  # the paper's update, step (3) after Eq. (28)
    return x, costs
