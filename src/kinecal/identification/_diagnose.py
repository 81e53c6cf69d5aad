"""What is worth telling about a solution: improbable rows, systematic residuals,
parameters the priors determine, parameters the poses hardly determine, overfitting."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from kinecal._log import Logger
from kinecal._record import Record
from kinecal.identification._options import PriorSettings, RejectSettings
from kinecal.identification._priors import build_prior
from kinecal.identification._problem import Problem, State
from kinecal.identification._robust import (
    find_outliers,
    residual_structure,
    systematic_diagnostic,
)
from kinecal.measurement._diagnostics import Diagnostic
from kinecal.typing import Float

__all__ = ["Diagnose"]

log = Logger(__name__)


@dataclass(frozen=True, eq=False, repr=False)
class Diagnose(Record):
    """Findings about the solution: ``outliers`` (rows improbable under the noise of the
    others, by their file lines) or ``systematic_residuals`` (when the largest errors
    follow the pose), ``loose_parameters`` and ``overfit_risk`` (``prior_dominated``:
    :class:`~kinecal.identification._uncertainty.Uncertainty`, from the prior's share of
    each variance)."""

    name: str = "diagnose"
    settings: RejectSettings | None = None  # None: from the problem's options
    priors: PriorSettings | None = None  # ... the default priors' scales too

    def __call__(self, problem: Problem, state: State) -> State:
        cm = state.model
        opts = self.settings or RejectSettings.of(problem.options)
        blk = problem.evaluations(cm, state.x, state.weights)
        found = []
        outliers = find_outliers(blk.r, blk.raw_position, problem.meas, opts.outlier_p)
        flagged = np.isin(problem.meas.rows, [o.row for o in outliers])
        err = np.linalg.norm(blk.raw_position, axis=1)
        st = residual_structure(problem, state, err, flagged)
        told = any(d.code == "systematic_residuals" for d in state.diagnostics)
        if st is not None and st.systematic:
            if not told:
                found.append(systematic_diagnostic(problem, state, st, self.name))
        elif outliers:
            found.append(_outlier_diagnostic(problem, outliers, opts))
        fidx = np.flatnonzero(state.free)
        std = state.std if state.std is not None else np.full(cm.size, np.nan)
        assert state.prior is not None and state.x_registered is not None
        priors = self.priors or PriorSettings.of(problem.options)
        loose = _loose_parameters(state, std, fidx, priors)
        if loose:
            found.append(
                Diagnostic(
                    "loose_parameters",
                    f"{len(loose)} parameters without a prior are hardly determined by "
                    "these poses: their standard deviation exceeds the size the default "
                    "priors allow (--priors all): "
                    + ", ".join(f"{name} ({ratio:.3g}x)" for name, ratio in loose[:8])
                    + (f" and {len(loose) - 8} more" if len(loose) > 8 else "")
                    + ".",
                    parameters=tuple(name for name, _ in loose),
                    stage=self.name,
                )
            )
        ratio = fidx.size / problem.n_residuals
        if ratio > 0.2:
            found.append(
                Diagnostic(
                    "overfit_risk",
                    f"{fidx.size} parameters from {problem.n_residuals} residuals "
                    f"({ratio:.0%}): results may overfit; validate on other poses.",
                    stage=self.name,
                )
            )
        if state.identifiability is not None:
            for d in state.identifiability.dropped:
                log.info("unidentifiable: %s", d.describe())
        return state.but(outliers=tuple(outliers)).note(*found)


def _outlier_diagnostic(
    problem: Problem, outliers: list, opts: RejectSettings
) -> Diagnostic:
    """Rows kept although improbable, with the reason and what else to do."""
    meas = problem.meas
    where = "file lines" if meas.source.endswith(".csv") else "rows"
    lines = ", ".join(f"{o.row} (z {o.z:.3g})" for o in outliers[:10])
    more = f" and {len(outliers) - 10} more" if len(outliers) > 10 else ""
    head = (
        f"{len(outliers)} rows have errors improbable under the noise of the others: "
        f"{where} {lines}{more}; "
    )
    if opts.loss != "linear":
        tail = f"down-weighted by the {opts.loss} loss."
    elif opts.reject == "off":
        tail = "kept (--reject auto removes gross errors)."
    else:
        tail = (
            "kept: they do not stand apart from the others (the noise has heavy "
            "tails), so they still inform the fit (--reject-z Z rejects every row "
            "beyond Z)."
        )
    return Diagnostic(
        "outliers",
        head + tail,
        rows=tuple(o.row for o in outliers),
        stage="diagnose",
    )


def _loose_parameters(
    state: State, std: Float, fidx: np.ndarray, priors: PriorSettings
) -> list[tuple[str, float]]:
    """Estimated parameters without a prior (``sigma`` infinite) whose standard
    deviation exceeds the prior ``--priors all`` would give them (their plausible size),
    as ``(name, std / that prior)``, largest first: plain least squares leaves them to
    the noise."""
    assert state.prior is not None and state.x_registered is not None
    cm = state.model
    sigma = state.prior.sigma
    plausible = build_prior(cm, state.x_registered, replace(priors, priors="all")).sigma
    out = [
        (cm.layout.names[i], float(std[i] / plausible[i]))
        for i in fidx
        if not np.isfinite(sigma[i])
        and np.isfinite(plausible[i])
        and std[i] > plausible[i]
    ]
    return sorted(out, key=lambda item: -item[1])
