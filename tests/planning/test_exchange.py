"""Greedy selection and the exchange algorithms."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from kinecal.planning import EXCHANGES, select_poses
from tests.planning.test_criteria import direct_value, synthetic_problem


@pytest.mark.parametrize("criterion", ["I", "D", "A"])
def test_exchange_finds_the_exhaustive_optimum_of_a_small_problem(rng, criterion):
    pb = synthetic_problem(rng, N=12, p=5)
    n = 3
    values = {
        rows: direct_value(pb, criterion, rows)
        for rows in itertools.combinations(range(12), n)
    }
    best = max(values.values())
    worst = min(values.values())
    greedy = select_poses(pb, n, criterion=criterion, exchange="none")
    for exchange in ("fedorov", "detmax"):
        sel = select_poses(pb, n, criterion=criterion, exchange=exchange)
        assert sel.value >= greedy.value - 1e-12
        assert sel.value == pytest.approx(
            direct_value(pb, criterion, sel.index), rel=1e-9
        )
        # a local optimum of single swaps: within a few per cent of the best subset
        # (of the whole range of subsets), and usually the best itself
        assert best - sel.value <= 0.05 * (best - worst)


def test_exchange_improves_on_greedy_and_keeps_poses_distinct(rng):
    pb = synthetic_problem(rng, N=80, p=9)
    greedy = select_poses(pb, 10, exchange="none")
    fed = select_poses(pb, 10, exchange="fedorov")
    assert fed.value >= greedy.value
    assert fed.greedy_value == pytest.approx(greedy.value)
    assert np.unique(fed.index).size == 10
    # no single swap improves the final design any further
    from kinecal.planning import DesignState

    st = DesignState(pb, "I")
    for k in fed.index:
        st.add(int(k))
    for k in fed.index:
        assert np.max(st.swap_values(int(k))) <= fed.value + 1e-5 * abs(fed.value)


def test_excluded_candidates_are_never_chosen_and_start_is_used(rng):
    pb = synthetic_problem(rng, N=30)
    excl = np.zeros(30, bool)
    excl[::2] = True
    sel = select_poses(pb, 6, exclude=excl)
    assert not excl[sel.index].any()
    start = np.array([1, 3, 5, 7, 9, 11])
    s2 = select_poses(pb, 6, start=start, exchange="none")
    assert sorted(s2.index) == list(start)
    assert s2.value == pytest.approx(direct_value(pb, "I", start), rel=1e-10)


def test_bad_arguments_are_refused(rng):
    pb = synthetic_problem(rng, N=10)
    with pytest.raises(
        ValueError, match=r"between 1 and 10 \(the candidates available\); got 11"
    ):
        select_poses(pb, 11)
    with pytest.raises(ValueError, match="between 1 and 10"):
        select_poses(pb, 0)
    with pytest.raises(ValueError, match="exchange must be one of"):
        select_poses(pb, 3, exchange="anneal")
    with pytest.raises(ValueError, match="start must hold 3 distinct"):
        select_poses(pb, 3, start=np.array([1, 1, 2]))
    assert set(EXCHANGES) == {"fedorov", "detmax", "none"}
