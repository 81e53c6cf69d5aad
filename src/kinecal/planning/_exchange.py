"""Choosing n of N candidate poses: greedy forward selection, then exchanges.

* Greedy: add the candidate that improves the criterion most, n times (every candidate
  scored at once, :class:`~kinecal.planning._criteria.DesignState`).
* Fedorov exchange, the modified form of Cook & Nachtsheim (Technometrics 22, 1980): take
  each design pose in turn, find the best candidate to put in its place, swap if that
  improves the criterion; repeat the sweep until no swap helps.
* DETMAX (Mitchell, Technometrics 16, 1974): excursions that add the best candidate and
  drop the worst pose (one, then two at a time) while the criterion improves.

Poses are distinct: a candidate is chosen at most once.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np

from kinecal.planning._criteria import DesignState
from kinecal.planning._design import DesignProblem
from kinecal.typing import Float

__all__ = ["EXCHANGES", "Selection", "select_poses"]

log = logging.getLogger(__name__)

EXCHANGES = ("fedorov", "detmax", "none")
# An exchange must improve the criterion by this fraction of its scale to be taken.
_REL_TOL = 1e-5


@dataclass
class Selection:
    """Result of :func:`select_poses`.

    Attributes
    ----------
    index : (n,) chosen candidates, in the order they entered.
    criterion : name of the criterion.
    value : its final value (larger is better; see :mod:`._criteria`).
    greedy_value : its value after the greedy phase.
    swaps : exchanges made.
    sweeps : exchange sweeps (Fedorov) or excursions (DETMAX) tried.
    seconds : time taken.
    history : criterion value after each accepted step.
    """

    index: np.ndarray
    criterion: str
    value: float
    greedy_value: float
    swaps: int
    sweeps: int
    seconds: float
    history: list[float] = field(default_factory=list)


def _tol(value: float) -> float:
    return _REL_TOL * max(abs(value), 1e-300) + 1e-300


def select_poses(
    problem: DesignProblem,
    n: int,
    *,
    criterion: str = "I",
    exchange: str = "fedorov",
    base: Float | None = None,
    exclude: np.ndarray | None = None,
    start: np.ndarray | None = None,
    max_sweeps: int = 20,
    screen: int = 24,
) -> Selection:
    """Choose ``n`` candidates of ``problem`` that optimise ``criterion``.

    Parameters
    ----------
    problem : DesignProblem
    n : int, poses to choose (1 <= n <= candidates).
    criterion : 'I' (default), 'D', 'A', 'E' or 'G' (:mod:`kinecal.planning._criteria`).
    exchange : 'fedorov' (default), 'detmax' or 'none' (greedy only).
    base : (p, p), optional
        Information already there (prior plus poses measured before: sequential design).
    exclude : (N,) bool, optional
        Candidates not to choose.
    start : (n,) int, optional
        A starting design instead of the greedy one.
    max_sweeps : bound on the exchange sweeps.
    screen : candidates scored exactly per step for E and G.

    Raises
    ------
    ValueError
        ``n`` out of range, unknown criterion or exchange.
    """
    t0 = time.perf_counter()
    N = problem.n_candidates
    excl = np.zeros(N, bool) if exclude is None else np.asarray(exclude, bool)
    if excl.shape != (N,):
        raise ValueError(f"exclude must have shape ({N},); got {excl.shape}.")
    avail = int(N - excl.sum())
    if not 1 <= n <= avail:
        raise ValueError(
            f"the number of poses must be between 1 and {avail} (the candidates "
            f"available); got {n}."
        )
    if exchange not in EXCHANGES:
        raise ValueError(
            f"exchange must be one of {', '.join(EXCHANGES)}; got {exchange!r}."
        )
    st = DesignState(problem, criterion, base, screen=screen)
    history: list[float] = []
    if start is not None:
        idx = np.asarray(start, np.intp)
        if idx.shape != (n,) or np.unique(idx).size != n or excl[idx].any():
            raise ValueError(
                f"start must hold {n} distinct candidates that are not excluded."
            )
        for k in idx:
            st.add(int(k))
    else:
        for _ in range(n):
            vals = st.add_values(excl)
            st.add(int(np.argmax(vals)))
            history.append(float(vals.max()))
    greedy = st.value()
    swaps = sweeps = 0
    if exchange == "fedorov":
        st, swaps, sweeps = _fedorov(st, excl, max_sweeps, history)
    elif exchange == "detmax":
        st, swaps, sweeps = _detmax(st, excl, max_sweeps * n, history)
    st.refresh()
    value = st.value()
    dt = time.perf_counter() - t0
    log.info(
        "%s-optimal %d of %d: greedy %.6g -> %.6g (%d swaps, %d sweeps, %.2f s)",
        criterion,
        n,
        N,
        greedy,
        value,
        swaps,
        sweeps,
        dt,
    )
    return Selection(
        np.array(st.selected, np.intp),
        criterion,
        value,
        greedy,
        swaps,
        sweeps,
        dt,
        history,
    )


def _fedorov(
    st: DesignState, excl: np.ndarray, max_sweeps: int, history: list[float]
) -> tuple[DesignState, int, int]:
    """Modified Fedorov exchange: per design pose, the best swap if it improves."""
    swaps = sweeps = 0
    for sweeps in range(1, max_sweeps + 1):  # noqa: B007 (reported)
        improved = False
        current = st.value()
        for k in list(st.selected):
            vals = st.swap_values(k, excl)
            best = int(np.argmax(vals))
            if vals[best] > current + _tol(current):
                st.remove(k)
                st.add(best)
                current = float(vals[best])
                history.append(current)
                swaps += 1
                improved = True
        if not improved:
            break
    return st, swaps, sweeps


def _detmax(
    st: DesignState, excl: np.ndarray, max_steps: int, history: list[float]
) -> tuple[DesignState, int, int]:
    """DETMAX excursions of depth 1 then 2: add the best, drop the worst."""
    swaps = steps = 0
    depth = 1
    while steps < max_steps and depth <= 2:
        steps += 1
        current = st.value()
        trial = st.copy()
        for _ in range(depth):
            vals = trial.add_values(excl)
            trial.add(int(np.argmax(vals)))
        for _ in range(depth):
            rv = trial.remove_values()
            trial.remove(trial.selected[int(np.argmax(rv))])
        new = trial.value()
        if new > current + _tol(current):
            st = trial
            history.append(new)
            swaps += 1
            depth = 1
        else:
            depth += 1
    return st, swaps, steps
