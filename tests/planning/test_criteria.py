"""The rank-c updates of the design criteria against direct evaluation."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from kinecal.planning import CRITERIA, DesignProblem, DesignState
from kinecal.planning._criteria import _inv3, _logdet


def synthetic_problem(rng, N=40, c=3, p=7) -> DesignProblem:
    """A design problem with random blocks (no robot needed)."""
    F = rng.normal(size=(N, c, p))
    G = rng.normal(size=(N, 3, p))
    prec = rng.uniform(0.05, 0.5, p)
    layout = SimpleNamespace(scales=np.ones(p), names=[f"x{k}" for k in range(p)])
    return DesignProblem(
        model=SimpleNamespace(layout=layout),  # type: ignore[arg-type]
        params=np.zeros(p),
        free=np.ones(p, bool),
        F=F,
        G=G,
        prior_precision=prec,
        has_prior=np.ones(p, bool),
        sigma=np.ones(N),
        identifiability=None,  # type: ignore[arg-type]
        weight=np.full(N, 1.0 / N),
    )


def direct_value(pb: DesignProblem, criterion: str, rows) -> float:
    """The criterion from the information matrix, inverted from scratch."""
    M = pb.information(np.asarray(rows, int))
    A = np.linalg.inv(M)
    if criterion == "D":
        return float(np.linalg.slogdet(M)[1])
    if criterion == "A":
        return -float(np.trace(A))
    if criterion == "I":
        W = np.einsum("n,nip,niq->pq", pb.weight, pb.G, pb.G)
        return -float(np.trace(A @ W))
    if criterion == "E":
        return float(np.linalg.eigvalsh(M)[0])
    return -float(np.max(np.einsum("nip,pq,niq->n", pb.G, A, pb.G)))


@pytest.mark.parametrize("c", [3, 6])
@pytest.mark.parametrize("criterion", CRITERIA)
def test_add_remove_swap_values_equal_direct_evaluation(rng, criterion, c):
    pb = synthetic_problem(rng, c=c)
    st = DesignState(pb, criterion, screen=pb.n_candidates)
    design = [3, 17, 5, 30, 22, 9]
    for k in design:
        st.add(k)
    assert st.value() == pytest.approx(direct_value(pb, criterion, design), rel=1e-10)
    add = st.add_values()
    for a in range(pb.n_candidates):
        if a in design:
            assert add[a] == -np.inf
        else:
            want = direct_value(pb, criterion, [*design, a])
            assert add[a] == pytest.approx(want, rel=1e-9, abs=1e-12)
    rem = st.remove_values()
    for j, k in enumerate(st.selected):
        want = direct_value(pb, criterion, [d for d in design if d != k])
        assert rem[j] == pytest.approx(want, rel=1e-9, abs=1e-12)
    k = design[2]
    sw = st.swap_values(k)
    rest = [d for d in design if d != k]
    for a in range(pb.n_candidates):
        if a in design:
            assert sw[a] == -np.inf
        else:
            assert sw[a] == pytest.approx(
                direct_value(pb, criterion, [*rest, a]), rel=1e-9, abs=1e-12
            )


def test_updates_stay_exact_over_many_changes(rng):
    """Rank-3 updates accumulate no visible round-off between refreshes."""
    pb = synthetic_problem(rng, N=60)
    st = DesignState(pb, "I")
    order = rng.permutation(60)
    for k in order[:30]:
        st.add(int(k))
    for k in order[:20]:
        st.remove(int(k))
    assert st.value() == pytest.approx(direct_value(pb, "I", order[20:30]), rel=1e-10)
    np.testing.assert_allclose(st.A, np.linalg.inv(st.M), rtol=1e-8, atol=1e-12)


def test_small_determinant_helpers_match_lapack(rng):
    S = rng.normal(size=(50, 3, 3))
    S = S @ np.swapaxes(S, 1, 2) + 0.1 * np.eye(3)
    inv, det = _inv3(S)
    np.testing.assert_allclose(inv, np.linalg.inv(S), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(det, np.linalg.det(S), rtol=1e-12)
    np.testing.assert_allclose(_logdet(S), np.linalg.slogdet(S)[1], rtol=1e-12)
    S[0] = -S[0]  # not positive definite: no log
    assert _logdet(S)[0] == -np.inf


def test_bad_criterion_and_base_are_refused(rng):
    pb = synthetic_problem(rng)
    with pytest.raises(ValueError, match="criterion must be one of I, D, A, E, G"):
        DesignState(pb, "X")
    with pytest.raises(ValueError, match=r"base must have shape \(7, 7\)"):
        DesignState(pb, "D", np.eye(3))
