"""The order in which to measure the chosen poses: a short tour through them.

The cost of a move is the largest joint motion ``max_j |q_a,j - q_b,j|`` (the joints
move together, so the slowest sets the time; equal joint speeds assumed). The tour starts
at the pose nearest the home pose, visits the nearest unvisited pose next, and is then
improved by 2-opt (reversing a stretch of the tour wherever that shortens it) until no
reversal helps. An open path: the robot does not return home.
"""

from __future__ import annotations

import numpy as np

from kinecal.typing import Float

__all__ = ["path_length", "tour"]


def _distances(q: Float) -> Float:
    """(n, n) largest joint motion between every pair of poses."""
    return np.max(np.abs(q[:, None, :] - q[None, :, :]), axis=2)


def path_length(q: Float, order: np.ndarray | None = None) -> float:
    """Sum of the largest joint motions along the poses in ``order`` [units of q]."""
    qq = q if order is None else q[np.asarray(order, np.intp)]
    if qq.shape[0] < 2:
        return 0.0
    return float(np.sum(np.max(np.abs(np.diff(qq, axis=0)), axis=1)))


def tour(q_ctrl: Float, home: Float | None = None, max_passes: int = 50) -> np.ndarray:
    """An order of the poses with short joint motion (nearest neighbour, then 2-opt).

    Parameters
    ----------
    q_ctrl : (n, J) poses [rad or any unit; the metric is the largest joint difference].
    home : (J,), the pose the robot starts from (default zeros).
    max_passes : bound on the 2-opt passes.

    Returns
    -------
    (n,) int, a permutation of the poses; the first is the nearest to ``home``.
    """
    q = np.asarray(q_ctrl, np.float64)
    n = q.shape[0]
    if n <= 2:
        h = np.zeros(q.shape[1]) if home is None else np.asarray(home, float)
        d0 = np.max(np.abs(q - h), axis=1)
        return np.argsort(d0, kind="stable")
    h = np.zeros(q.shape[1]) if home is None else np.asarray(home, float)
    D = _distances(q)
    start = int(np.argmin(np.max(np.abs(q - h), axis=1)))
    order = [start]
    free = np.ones(n, bool)
    free[start] = False
    for _ in range(n - 1):
        d = np.where(free, D[order[-1]], np.inf)
        k = int(np.argmin(d))
        order.append(k)
        free[k] = False
    path = np.array(order, np.intp)
    # 2-opt on the open path with a fixed start: reversing path[i..j] replaces the edges
    # (i-1, i) and (j, j+1) by (i-1, j) and (i, j+1) (no edge after the last pose).
    for _ in range(max_passes):
        improved = False
        for i in range(1, n - 1):
            a = path[i - 1]
            b = path[i]
            j = np.arange(i + 1, n)
            c = path[j]
            nxt = np.where(j + 1 < n, path[np.minimum(j + 1, n - 1)], -1)
            old = D[a, b] + np.where(nxt >= 0, D[c, np.maximum(nxt, 0)], 0.0)
            new = D[a, c] + np.where(nxt >= 0, D[b, np.maximum(nxt, 0)], 0.0)
            gain = old - new
            k = int(np.argmax(gain))
            if gain[k] > 1e-12:
                jj = int(j[k])
                path[i : jj + 1] = path[i : jj + 1][::-1].copy()
                improved = True
        if not improved:
            break
    return path
