"""Parameter recovery: estimates against the simulated truth.

Parameters the poses cannot determine are held at their start values, and their effect is
absorbed by others (a constant NTM term by the joint offset, d3 by d2 ...). And when the
truth has effects outside the model, the other parameters absorb those as well, in a way
that depends on the poses. The values an estimator can recover are therefore those of the
*equivalent truth*: the fitted model, with the same parameters held, adjusted to the
noise-free truth at the calibration poses (the pseudo-true parameters of that design).
Recovery is judged against it, in units of the reported standard deviation.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from kinecal.identification import CalibrationResult, LMOptions, solve_lm
from kinecal.measurement import Measurements, residuals
from kinecal.simulation._truth import TrueRobot
from kinecal.typing import Float

__all__ = ["Recovery", "noise_free", "parameter_recovery"]


def noise_free(truth: TrueRobot, meas: Measurements) -> Measurements:
    """``meas`` with every measurement replaced by the truth's exact value."""
    if meas.kind == "sensor":
        assert meas.targets is not None and meas.target_index is not None
        p0, R = truth.evaluate(meas.q_ctrl, orientation=True)
        assert R is not None
        p_cam = np.einsum("nji,nj->ni", R, meas.targets[meas.target_index] - p0)
        return replace(meas, p=p_cam, sigma=None)
    p, R = truth.evaluate(meas.q_ctrl, orientation=meas.kind == "pose")
    return replace(meas, p=p, R_user_cam=R if meas.kind == "pose" else None, sigma=None)


@dataclass
class Recovery:
    """Estimates, equivalent truth and z-scores of the estimated parameters."""

    names: list[str]
    estimate: Float
    std: Float
    equivalent: Float
    raw_truth: Float  # NaN where the truth model has no such parameter
    z: Float
    fit_rms_mm: float  # how well the fitted model can represent the truth

    @property
    def max_abs_z(self) -> float:
        return float(np.nanmax(np.abs(self.z))) if self.z.size else float("nan")

    def fraction_within(self, k: float) -> float:
        return float(np.mean(np.abs(self.z) <= k)) if self.z.size else float("nan")


def parameter_recovery(
    result: CalibrationResult, truth: TrueRobot, poses: Measurements
) -> Recovery:
    """Compare a calibration with the truth; ``poses`` should be the calibration poses.

    The equivalent truth minimises the same objective as the calibration (same weights,
    same priors, same parameters held) on the noise-free measurements.
    """
    cal = result.calibrated
    model = cal.model
    exact = noise_free(truth, poses)
    inputs = exact.model_inputs(cal.reference_payload_kg)
    free = np.array([s == "estimated" for s in cal.status])

    def fun(x: Float, jac: bool) -> tuple[Float, Float | None]:
        blk = residuals(model, x, exact, result.weights, inputs=inputs, jacobian=jac)
        return blk.r, blk.J

    eq = solve_lm(
        fun,
        cal.params,
        free,
        model.layout.scales,
        LMOptions(max_iter=200),
        prior=result.prior,
        label="equivalent truth",
    ).x
    blk = residuals(model, eq, exact, result.weights, inputs=inputs)
    fit_rms = float(np.sqrt(np.mean(np.sum(blk.raw_position**2, axis=1)))) * 1e3
    L = model.layout
    idx = np.flatnonzero(free)
    names = [L.names[i] for i in idx]
    raw = np.array(
        [
            truth.params[truth.model.layout.index(n)]
            if n in truth.model.layout
            else np.nan
            for n in names
        ]
    )
    z = (cal.params[idx] - eq[idx]) / cal.std[idx]
    return Recovery(names, cal.params[idx], cal.std[idx], eq[idx], raw, z, fit_rms)
