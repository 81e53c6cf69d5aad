"""The noise model from the data: variance components, and how to weigh orientations.

Without sigmas in the data, kinecal estimates the noise from the residuals of each fit by
Helmert's variance component estimation (Eq. (T-7)): for each group ``g`` of residual
components (positions; orientations; per set or marker where those differ) with its part
``N_g = J_gᵀ J_g`` of the normal matrix ``N = Σ N_g + P`` (whitened, with the priors),

    σ_g² ← σ_g² · ‖r_g‖² / (n_g − tr(N⁻¹ N_g)),

iterated at the linearisation point until the factors settle. The redundancy
``n_g − tr(N⁻¹ N_g)`` is the share of the degrees of freedom the group keeps after the
fit (the parameters a group determines alone do not leave it residuals).

A group split (per set, per marker) is kept when a group's variance differs from the rest
beyond three standard deviations of the log ratio (``2/r_1 + 2/r_2``) and by 20 %.

For pose data the residuals say how noisy orientations are, not whether they help predict
positions (a camera's orientation errors may follow the pose and mislead the fit).
:class:`NoiseModel` therefore also tries the orientation sigma at 0.25-10 times its
estimate and keeps the factor that predicts positions best, by the leave-one-out errors of
the linearised fit (:mod:`._press`), when it improves them by more than 1 %. On the shipped
FR3 camera data that is 10x (cross-validated 1.44 -> 1.36 mm, as with positions alone); on
the UR10 motion capture data orientations keep their weight.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from kinecal._log import Logger
from kinecal._record import Record
from kinecal._stats import median, present
from kinecal.identification._lm import Prior
from kinecal.identification._problem import Problem, State
from kinecal.identification._solve import run_lm
from kinecal.measurement._diagnostics import Diagnostic
from kinecal.measurement._measurements import Measurements
from kinecal.measurement._residuals import ResidualBlock, Weights
from kinecal.typing import Float

__all__ = ["NoiseModel", "estimate_noise", "helmert"]

log = Logger(__name__)

_FACTORS = (0.25, 0.5, 1.0, 2.0, 4.0, 10.0)
_SPLIT_Z = 3.0
_SPLIT_RATIO = 1.2


Grouped = tuple[list[Float], Float, Float]


def _group_normals(J: Float, r: Float, groups: np.ndarray, n_groups: int) -> Grouped:
    """Per group: the normal matrix part, the count of components and ``‖r‖²``."""
    k = J.shape[-1]
    Ns, counts, sq = [], np.zeros(n_groups), np.zeros(n_groups)
    for g in range(n_groups):
        sel = groups == g
        Jg = J[sel].reshape(-1, k)
        Ns.append(Jg.T @ Jg)
        counts[g] = sel.sum()
        sq[g] = float(np.sum(r[sel] ** 2))
    return Ns, counts, sq


def _components(grouped: Grouped, P: Float) -> tuple[Float, Float]:
    """Helmert factors ``σ_g,new / σ_g`` and redundancies of component groups.

    ``grouped``: per group the part of the normal matrix (k, k), the count of its
    components and their ``‖r‖²`` (whitened); ``P`` (k, k) the prior precision (scaled).
    """
    Ns, counts, sq = grouped
    n_groups = len(Ns)
    factor = np.ones(n_groups)
    red = counts.copy()
    for _ in range(20):
        N = P + sum(Ng / f**2 for Ng, f in zip(Ns, factor))
        Ni = np.linalg.pinv(N, rcond=1e-12, hermitian=True)
        red = np.array(
            [
                c - float(np.sum(Ni * (Ng / f**2)))
                for c, Ng, f in zip(counts, Ns, factor)
            ]
        )
        new = np.sqrt(
            np.maximum(sq / factor**2, 0.0) / np.maximum(red, 1e-9)
        )  # Eq. (T-7)
        new = np.where(counts > 0, new, 1.0)
        factor = factor * new
        if np.all(np.abs(new - 1.0) < 1e-4):
            break
    return factor, red


def helmert(
    problem: Problem, state: State, x: Float, free: np.ndarray, prior: Prior | None
) -> tuple[Weights, list[str]]:
    """Noise per row from the residuals of the fit of ``free`` at ``x`` (module docs).

    Returns
    -------
    weights : the sigmas (per row; one value per group).
    groups : how the components were grouped, in words (e.g. ``positions per set``).
    """
    meas = problem.meas
    cm, w = state.model, state.weights
    blk = problem.evaluations(cm, x, w, jacobian=True)
    fidx = np.flatnonzero(free)
    sc = cm.layout.scales[fidx]
    P = (
        np.zeros((fidx.size, fidx.size))
        if prior is None
        else np.diag(prior.precision[fidx] * sc**2)
    )
    N, c = blk.r.shape
    kinds = [("positions", slice(0, 3), w.sigma)]
    if c == 6:
        assert w.sigma_rot is not None
        kinds.append(("orientations", slice(3, 6), w.sigma_rot))
    splits = [("", np.zeros(N, np.intp))]
    if len(meas.set_labels) > 1:
        splits.append(("per set", meas.set_index))
    if len(meas.marker_labels) > 1:
        splits.append(("per marker", meas.marker_index))
    if blk.J is not None:
        grouped, others = _held_groups(blk.J[:, :, fidx] * sc, blk.r, kinds)
    else:  # large data: every group's part summed in one pass over blocks of poses
        grouped, others = _block_groups(blk, fidx, sc, kinds, meas)
    out_sigma: list[Float] = []
    words = []
    for kind, _, sigma in kinds:
        # The other kinds stay in the normal matrix as one fixed group.
        P_k = P.copy()
        for o in others[kind]:
            P_k = P_k + o
        best_label, best_idx, best_z = "", np.zeros(N, np.intp), 0.0
        for label, idx in splits[1:]:
            f, red = _components(grouped(kind, idx), P_k)
            z = _split_z(f, red)
            if z > max(best_z, _SPLIT_Z) and f.max() / f.min() > _SPLIT_RATIO:
                best_label, best_idx, best_z = label, idx, z
        f, _ = _components(grouped(kind, best_idx), P_k)
        out_sigma.append(np.maximum(sigma * f[best_idx], 1e-12))
        words.append(f"{kind} {best_label}".strip())
    weights = Weights(out_sigma[0], out_sigma[1] if len(out_sigma) > 1 else None)
    return weights, words


Kinds = list[tuple[str, slice, Float]]
GroupFn = Callable[[str, np.ndarray], Grouped]


def _held_groups(
    J: Float, r: Float, kinds: Kinds
) -> tuple[GroupFn, dict[str, list[Float]]]:
    """Group parts of the normal matrix from a held Jacobian (N, c, k), scaled."""
    k = J.shape[-1]
    Jks = {kind: J[:, cols].reshape(-1, k) for kind, cols, _ in kinds}
    rks = {kind: r[:, cols].reshape(-1) for kind, cols, _ in kinds}

    def grouped(kind: str, idx: np.ndarray) -> Grouped:
        n_g = int(idx.max()) + 1
        return _group_normals(Jks[kind], rks[kind], np.repeat(idx, 3), n_g)

    others = {
        kind: [Jks[o].T @ Jks[o] for o, _, _ in kinds if o != kind]
        for kind, _, _ in kinds
    }
    return grouped, others


def _block_groups(
    blk: ResidualBlock, fidx: np.ndarray, sc: Float, kinds: Kinds, meas: Measurements
) -> tuple[GroupFn, dict[str, list[Float]]]:
    """Group parts of the normal matrix by one pass over blocks of poses: per kind, set
    and marker; a grouping by set or marker sums them."""
    S, M, k = len(meas.set_labels), len(meas.marker_labels), fidx.size
    parts = {kind: np.zeros((S, M, k, k)) for kind, _, _ in kinds}
    cols_of = {kind: cols for kind, cols, _ in kinds}
    cell = meas.set_index * M + meas.marker_index
    cells = present(cell)
    for rows, Jb in blk.jacobian_blocks():
        J = Jb[:, :, fidx] * sc
        cb = cell[rows]
        for kind, cols, _ in kinds:
            for cc in cells:
                Jg = J[cb == cc][:, cols].reshape(-1, k)
                if Jg.size:
                    parts[kind][cc // M, cc % M] += Jg.T @ Jg

    def grouped(kind: str, idx: np.ndarray) -> Grouped:
        n_g = int(idx.max()) + 1
        Ns = [np.zeros((k, k)) for _ in range(n_g)]
        for cc in cells:
            g = int(idx[np.argmax(cell == cc)])  # every row of a cell is in one group
            Ns[g] = Ns[g] + parts[kind][cc // M, cc % M]
        r2 = np.sum(blk.r[:, cols_of[kind]] ** 2, axis=1)
        counts = 3.0 * np.bincount(idx, minlength=n_g).astype(np.float64)
        sq = np.bincount(idx, weights=r2, minlength=n_g).astype(np.float64)
        return Ns, counts, sq

    others = {
        kind: [parts[o].sum(axis=(0, 1)) for o, _, _ in kinds if o != kind]
        for kind, _, _ in kinds
    }
    return grouped, others


def estimate_noise(
    problem: Problem, state: State, x: Float, free: np.ndarray, prior: Prior | None
) -> State:
    """The state with the noise estimated from the residuals of the fit of ``free`` at
    ``x`` (:func:`helmert`) as its weights."""
    weights, groups = helmert(problem, state, x, free, prior)
    return state.but(
        weights=weights, noise_estimated=True, noise_groups=tuple(groups), noise=None
    )


def _split_z(factor: Float, red: Float) -> float:
    """Largest standardised log variance ratio of a group against the others."""
    var = factor**2
    best = 0.0
    for g in range(factor.size):
        rest = np.delete(np.arange(factor.size), g)
        if red[g] < 2 or red[rest].sum() < 2:
            continue
        pooled = float(np.sum(var[rest] * red[rest]) / red[rest].sum())
        se = np.sqrt(2.0 / red[g] + 2.0 / red[rest].sum())
        best = max(best, abs(float(np.log(var[g] / pooled))) / se)
    return best


@dataclass(frozen=True, eq=False, repr=False)
class NoiseModel(Record):
    """For pose data without sigmas: the orientation weight that predicts positions best
    (module docs), and stage 3 again when it changes; a ``noise_model`` diagnostic with
    the variance components either way."""

    name: str = "noise model"

    def __call__(self, problem: Problem, state: State) -> State:
        meas = problem.meas
        if (
            meas.kind != "pose"
            or not problem.estimate_noise
            or meas.sigma_rot is not None
        ):
            return _noted(state, "")
        from kinecal.identification._press import loo_position_errors, rms_mm

        w = state.weights
        assert w.sigma_rot is not None
        press = {
            f: rms_mm(
                loo_position_errors(
                    problem,
                    state,
                    Weights(w.sigma, w.sigma_rot * f) if f != 1 else None,
                )
            )
            for f in _FACTORS
        }
        best = min(press, key=lambda f: press[f])
        if best == 1.0 or press[best] > 0.99 * press[1.0]:
            return _noted(state, "")
        weights = Weights(w.sigma, w.sigma_rot * best)
        state = state.but(weights=weights)
        lm3 = replace(state.lm, max_iter=max(state.lm.max_iter, 200))
        state, res = run_lm(
            problem,
            state,
            "stage 3: all (orientation weight)",
            state.x,
            state.free,
            lm3,
            state.active_prior(),
            lifted=True,
        )
        why = (
            f"; orientations weighted as {np.degrees(median(w.sigma_rot) * best):.3g} "
            f"deg ({best:g}x their noise), which predicts positions best (leave-one-out "
            f"RMS {press[1.0]:.4g} -> {press[best]:.4g} mm)"
        )
        return _noted(state.but(x=res.x, noise=w), why)


def _noted(state: State, extra: str) -> State:
    """The ``noise_model`` diagnostic: the variance components, and any reweighting."""
    noise = state.noise if state.noise is not None else state.weights
    if not state.noise_estimated:
        return state
    text = f"noise from the residuals (Helmert): positions {median(noise.sigma) * 1e3:.3g} mm"
    if noise.sigma_rot is not None:
        text += f", orientations {np.degrees(median(noise.sigma_rot)):.3g} deg"
    if state.noise_groups:
        text += f" ({', '.join(state.noise_groups)})"
    return state.note(
        Diagnostic(
            "noise_model", text + extra + ".", stage="noise model", severity="info"
        )
    )
