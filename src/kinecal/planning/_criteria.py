"""Optimal-design criteria on the posterior information, with rank-c updates.

With ``M`` the information of the design (prior included), ``A = M^-1`` and the
information block ``F_c`` (c x p) of a candidate, adding the candidate changes

.. math:: \\log\\det M' = \\log\\det M + \\log\\det S_c, \\qquad S_c = I + F_c A F_c^T

.. math:: \\mathrm{tr}(A' Q) = \\mathrm{tr}(A Q) - \\mathrm{tr}(S_c^{-1} F_c A Q A F_c^T)

(Sherman-Morrison-Woodbury), so every candidate is scored at once from ``B = F A``
(N, c, p) and ``C = B Q``, and one addition or removal updates ``A``, ``B`` and ``C`` by a
rank-c correction instead of a new inverse. Criteria, all to be maximised here:

* ``D``: ``log det M`` (the volume of the confidence ellipsoid);
* ``A``: ``-tr(M^-1)`` (mean variance of the scaled parameters);
* ``I``: ``-tr(M^-1 W)``, ``W = sum_c w_c G_c^T G_c``: minus the average variance of the
  predicted point over the candidates, the held-out error a user cares about;
* ``E``: ``lambda_min(M)`` (the worst determined direction);
* ``G``: ``-max_c tr(G_c M^-1 G_c^T)`` (the worst predicted candidate).

D, A and I are scored exactly for every candidate; E and G, which have no cheap update,
exactly for the ``screen`` candidates of largest D gain.
"""

from __future__ import annotations

import numpy as np

from kinecal.planning._design import DesignProblem
from kinecal.typing import Float

__all__ = ["CRITERIA", "DesignState"]

CRITERIA = ("I", "D", "A", "E", "G")
# Recompute the inverse from the information after this many rank-c updates (round-off
# of the updates stays far below the differences the search compares).
_REFRESH = 24


def _inv3(S: Float) -> tuple[Float, Float]:
    """Inverses and determinants of a stack of 3 x 3 matrices (K, 3, 3), by cofactors
    (several times faster than LAPACK's per-matrix calls at this size)."""
    a, b, c = S[:, 0, 0], S[:, 0, 1], S[:, 0, 2]
    d, e, f = S[:, 1, 0], S[:, 1, 1], S[:, 1, 2]
    g, h, i = S[:, 2, 0], S[:, 2, 1], S[:, 2, 2]
    c00, c01, c02 = e * i - f * h, f * g - d * i, d * h - e * g
    det = a * c00 + b * c01 + c * c02
    adj = np.empty_like(S)
    adj[:, 0, 0], adj[:, 1, 0], adj[:, 2, 0] = c00, c01, c02
    adj[:, 0, 1], adj[:, 0, 2] = c * h - b * i, b * f - c * e
    adj[:, 1, 1], adj[:, 1, 2] = a * i - c * g, c * d - a * f
    adj[:, 2, 1], adj[:, 2, 2] = b * g - a * h, a * e - b * d
    with np.errstate(divide="ignore", invalid="ignore"):
        return adj / det[:, None, None], det


def _logdet(S: Float) -> Float:
    """log det of a stack of symmetric positive definite matrices (-inf if not)."""
    if S.shape[-1] == 3:
        det = _inv3(S)[1]
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(det > 0, np.log(np.where(det > 0, det, 1.0)), -np.inf)
    sign, ld = np.linalg.slogdet(S)
    return np.where(sign > 0, ld, -np.inf)


def _trace_solve(S: Float, H: Float) -> Float:
    """``tr(S_k^-1 H_k)`` of stacks of symmetric c x c matrices (K,)."""
    Si = _inv3(S)[0] if S.shape[-1] == 3 else np.asarray(np.linalg.inv(S), np.float64)
    return np.sum(Si * H, axis=(1, 2))  # H symmetric: tr(Si H) = sum(Si * H^T)


def _t(X: Float) -> Float:
    """Contiguous transposes of a stack of matrices (stacked products are much faster on
    contiguous operands)."""
    return np.ascontiguousarray(np.swapaxes(X, 1, 2))


def _inv_spd(M: Float) -> Float:
    L = np.linalg.cholesky(M)
    Li = np.linalg.solve(L, np.eye(M.shape[0]))
    return Li.T @ Li


class DesignState:
    """A design under construction: its information, inverse and the candidates' terms.

    Parameters
    ----------
    problem : DesignProblem
    criterion : one of :data:`CRITERIA`
    base : (p, p), optional
        Information before any selected pose (default: the prior): existing data for a
        sequential design.
    screen : int
        Candidates scored exactly for E and G (the largest D gains).
    """

    def __init__(
        self,
        problem: DesignProblem,
        criterion: str = "I",
        base: Float | None = None,
        *,
        screen: int = 24,
    ) -> None:
        if criterion not in CRITERIA:
            raise ValueError(
                f"criterion must be one of {', '.join(CRITERIA)}; got {criterion!r}."
            )
        self.pb = problem
        self.criterion = criterion
        p = problem.size
        self.base = (
            np.diag(problem.prior_precision) if base is None else np.array(base, float)
        )
        if self.base.shape != (p, p):
            raise ValueError(f"base must have shape ({p}, {p}); got {self.base.shape}.")
        self.screen = max(int(screen), 1)
        self.Q: Float | None = None
        if criterion == "A":
            self.Q = np.eye(p)
        elif criterion == "I":
            self.Q = problem.moment
        self.selected: list[int] = []
        self.mask = np.zeros(problem.n_candidates, bool)
        self.M = self.base.copy()
        self._Ft = _t(problem.F)  # (N, p, c)
        self._updates = 0
        self.refresh()

    # ------------------------------------------------------------------ state
    def refresh(self) -> None:
        """Recompute ``A``, ``B``, ``C`` from the information."""
        pb = self.pb
        self.A = _inv_spd(self.M)
        self.B = pb.F @ self.A  # (N, c, p)
        self.C = None if self.Q is None else self.B @ self.Q
        self.GA = pb.G @ self.A if self.criterion == "G" else None
        self._updates = 0
        self._kh: tuple[Float, Float | None] | None = None

    def copy(self) -> DesignState:
        other = object.__new__(DesignState)
        other.__dict__.update(self.__dict__)
        other.selected = list(self.selected)
        other.mask = self.mask.copy()
        for k in ("M", "A", "B", "C", "GA"):
            v = getattr(self, k)
            setattr(other, k, None if v is None else v.copy())
        return other

    def _update(self, k: int, sign: float) -> None:
        """Add (``sign`` +1) or remove (-1) candidate ``k`` by a rank-c update."""
        Fk = self.pb.F[k]  # (c, p)
        Bk = self.B[k].copy()
        S = np.eye(Fk.shape[0]) + sign * (Bk @ Fk.T)
        Si = np.linalg.inv(S)
        self.M += sign * (Fk.T @ Fk)
        self.A -= sign * (Bk.T @ Si @ Bk)
        p = Fk.shape[1]
        B2 = self.B.reshape(-1, p)  # (N c, p) views: one matrix product each
        XS = (B2 @ Fk.T) @ Si  # F A F_k^T S^-1, (N c, c)
        if self.C is not None:
            Ck = self.C[k].copy()
            C2 = self.C.reshape(-1, p)
            C2 -= sign * (XS @ Ck)
        if self.GA is not None:
            GA2 = self.GA.reshape(-1, p)
            GA2 -= sign * (((GA2 @ Fk.T) @ Si) @ Bk)
        B2 -= sign * (XS @ Bk)
        self._kh = None
        self._updates += 1
        if self._updates >= _REFRESH:
            self.refresh()

    def add(self, k: int) -> None:
        self._update(k, 1.0)
        self.selected.append(int(k))
        self.mask[k] = True

    def remove(self, k: int) -> None:
        self.selected.remove(int(k))
        self.mask[k] = False
        self._update(k, -1.0)

    # ------------------------------------------------------------------ values
    def value(self) -> float:
        """The criterion of the current design (larger is better)."""
        c = self.criterion
        if c == "D":
            sign, logdet = np.linalg.slogdet(self.M)
            return float(logdet) if sign > 0 else -np.inf
        if c in ("A", "I"):
            assert self.Q is not None
            return -float(np.sum(self.A * self.Q))
        if c == "E":
            return float(np.linalg.eigvalsh(self.M)[0])
        return -float(np.max(self._pred_var()))

    def _pred_var(self) -> Float:
        """Variance of the predicted point at each candidate (sum over axes) [m^2]."""
        assert self.GA is not None
        return np.einsum("nip,nip->n", self.GA, self.pb.G)

    def _gram(self, rows: np.ndarray | slice) -> Float:
        """``F_k A F_k^T`` (K, c, c) of candidates ``rows``."""
        return self.B[rows] @ self._Ft[rows]

    def _terms(self) -> tuple[Float, Float | None]:
        """``K = F A F^T`` and (A, I) ``H = F A Q A F^T`` of every candidate, (N, c, c);
        kept until the design changes."""
        if self._kh is None:
            H = None
            if self.C is not None:
                H = self.C @ _t(self.B)
            self._kh = (self._gram(slice(None)), H)
        return self._kh

    def add_values(self, exclude: np.ndarray | None = None) -> Float:
        """Criterion after adding each candidate (N,); ``-inf`` for the selected ones,
        ``exclude``, and (E, G) those outside the screened set."""
        c = self.pb.rows
        K, H = self._terms()
        S = K + np.eye(c)
        skip = self.mask if exclude is None else (self.mask | exclude)
        if self.criterion == "D":
            out = self.value() + _logdet(S)
        elif self.criterion in ("A", "I"):
            assert H is not None
            out = self.value() + _trace_solve(S, H)
        else:
            gain = _logdet(S)
            gain[skip] = -np.inf
            m = min(self.screen, int(np.sum(~skip)))
            top = np.argpartition(-gain, m - 1)[:m] if m > 0 else np.zeros(0, int)
            out = np.full(self.pb.n_candidates, -np.inf)
            out[top] = self._exact(top, S[top], 1.0)
            return out
        out = np.asarray(out, np.float64)
        out[skip] = -np.inf
        return out

    def swap_values(self, k: int, exclude: np.ndarray | None = None) -> Float:
        """Criterion after replacing the design pose ``k`` by each candidate (N,).

        For D, A and I without updating the state: with ``T = I - F_k A F_k^T`` and
        ``X_a = F_a A F_k^T``, removing k turns ``F_a A F_a^T`` into
        ``K_a + X_a T^-1 X_a^T`` and ``F_a A`` into ``F_a A + X_a T^-1 F_k A``, so every
        term of :meth:`add_values` follows from c x c blocks. E and G: by a trial state.
        """
        skip = self.mask if exclude is None else (self.mask | exclude)
        if self.criterion not in ("D", "A", "I"):
            trial = self.copy()
            trial.remove(k)
            out = trial.add_values(exclude)
            out[skip] = -np.inf
            return out
        c = self.pb.rows
        p = self.pb.size
        N = self.pb.n_candidates
        K, H = self._terms()
        Fk, Bk = self.pb.F[k], self.B[k]
        T = np.eye(c) - Bk @ Fk.T
        Ti = np.linalg.inv(T)
        X2 = self.B.reshape(-1, p) @ Fk.T  # F_a A F_k^T, (N c, c)
        XT2 = X2 @ Ti
        XT = XT2.reshape(N, c, c)
        S = np.eye(c) + K + XT @ _t(X2.reshape(N, c, c))
        if self.criterion == "D":
            out = self.value() + _logdet(T[None])[0] + _logdet(S)
        else:
            assert self.C is not None and H is not None
            Hk = self.C[k] @ Bk.T  # F_k A Q A F_k^T
            Y = (self.C.reshape(-1, p) @ Bk.T).reshape(N, c, c)  # F_a A Q A F_k^T
            XTt = _t(XT)
            Hr = H + XT @ _t(Y) + Y @ XTt + (XT2 @ Hk).reshape(N, c, c) @ XTt
            removed = self.value() - float(np.trace(Ti @ Hk))
            out = removed + _trace_solve(S, Hr)
        out = np.asarray(out, np.float64)
        out[skip] = -np.inf
        return out

    def remove_values(self) -> Float:
        """Criterion after removing each selected pose, in the order of ``selected``."""
        sel = np.array(self.selected, np.intp)
        c = self.pb.rows
        S = np.eye(c) - self._gram(sel)
        if self.criterion == "D":
            return self.value() + _logdet(S)
        if self.criterion in ("A", "I"):
            assert self.C is not None
            H = self.C[sel] @ _t(self.B[sel])
            inc = _trace_solve(S, H)
            return np.where(np.isfinite(inc), self.value() - inc, -np.inf)
        return self._exact(sel, S, -1.0)

    def _exact(self, rows: np.ndarray, S: Float, sign: float) -> Float:
        """E or G criterion after adding (``sign`` +1) or removing (-1) each of ``rows``;
        ``S = I + sign F A F^T`` of those rows."""
        Fr = self.pb.F[rows]  # (K, c, p)
        if self.criterion == "E":
            Ms = self.M[None] + sign * (np.swapaxes(Fr, 1, 2) @ Fr)
            return np.linalg.eigvalsh(Ms)[:, 0]
        assert self.GA is not None
        N, _, p = self.GA.shape
        K, c, _ = Fr.shape
        # F_k A G_n^T of every screened row k and candidate n at once: (K, c, 3N)
        Y = (Fr.reshape(-1, p) @ self.GA.reshape(-1, p).T).reshape(K, c, 3 * N)
        Z = np.linalg.pinv(S, hermitian=True) @ Y
        dv = np.sum((Z * Y).reshape(K, c * N, 3), axis=2).reshape(K, c, N).sum(axis=1)
        return -np.max(self._pred_var()[None, :] - sign * dv, axis=1)
