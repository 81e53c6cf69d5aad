"""Measuring order: a short tour through the chosen poses."""

from __future__ import annotations

import itertools

import numpy as np

from kinecal.planning import path_length, tour


def test_tour_is_a_permutation_starting_near_home(rng):
    q = rng.uniform(-3, 3, size=(40, 6))
    order = tour(q)
    assert sorted(order) == list(range(40))
    assert order[0] == np.argmin(np.max(np.abs(q), axis=1))
    home = q[17] + 0.01
    assert tour(q, home)[0] == 17


def test_tour_is_much_shorter_than_a_random_order(rng):
    q = rng.uniform(-3, 3, size=(60, 6))
    order = tour(q)
    rand = np.mean([path_length(q, rng.permutation(60)) for _ in range(20)])
    assert path_length(q, order) < 0.6 * rand


def test_two_opt_reaches_the_exhaustive_optimum_of_small_tours(rng):
    hits = 0
    for _ in range(10):
        q = rng.uniform(-3, 3, size=(7, 3))
        order = tour(q)
        start = order[0]
        others = [i for i in range(7) if i != start]
        best = min(path_length(q, [start, *p]) for p in itertools.permutations(others))
        got = path_length(q, order)
        assert got <= 1.25 * best
        hits += np.isclose(got, best)
    assert hits >= 6  # 2-opt is a local search: usually, not always, the optimum


def test_degenerate_sizes():
    assert list(tour(np.zeros((1, 6)))) == [0]
    assert sorted(tour(np.array([[1.0, 0], [0.1, 0]]))) == [0, 1]
    assert tour(np.array([[1.0, 0], [0.1, 0]]))[0] == 1
    assert path_length(np.zeros((1, 3))) == 0.0
