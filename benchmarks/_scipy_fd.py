"""The scipy baseline as a whole process, like ``kinecal calibrate`` is measured.

``python -m benchmarks._scipy_fd CASE.npz POSES.csv OUT.npy [X_SCALE]`` reads the poses
from the CSV file (as the command does), builds the model that CASE describes, and fits it
from CASE's start with scipy's ``least_squares`` and finite-difference Jacobians, the same
fit as the in-process baseline of :mod:`benchmarks.__main__`; it writes the parameters to
OUT. X_SCALE is ``jac`` (the main benchmark's setting, the default) or ``1`` (scipy's own
default): on the twin's 2000 poses scipy's default needs 12 Jacobians where ``jac``
needs 54, and is the fairer anchor (issue 36).
"""

from __future__ import annotations

import json
import sys
from typing import Any

import numpy as np


def fd_fit(
    model: Any,
    x0: Any,
    free: Any,
    meas: Any,
    w: Any,
    inputs: Any,
    x_scale: str | float = "jac",
) -> Any:
    """The baseline: scipy's ``least_squares`` with 2-point finite differences over the
    ``free`` parameters from ``x0``, on the model's whitened residuals; the parameters."""
    from scipy.optimize import least_squares

    from kinecal.identification import residuals

    def f(z: np.ndarray) -> np.ndarray:
        x = x0.copy()
        x[free] = z
        return residuals(model, x, meas, w, inputs=inputs).r.reshape(-1)

    sol = least_squares(f, x0[free], jac="2-point", method="trf", x_scale=x_scale)
    x = x0.copy()
    x[free] = sol.x
    return x


def main(argv: list[str]) -> int:
    from kinecal.identification import Weights
    from kinecal.io import read_measurements
    from kinecal.models import CalibrationModel, ModelSpec
    from kinecal.robot import load_robot

    case, csv, out = argv[:3]
    x_scale: str | float = (
        "jac" if len(argv) < 4 or argv[3] == "jac" else float(argv[3])
    )
    data = np.load(case)
    robot = load_robot(str(data["robot"]))
    meas = read_measurements(csv, robot)
    spec = ModelSpec(
        **{
            k: tuple(v) if isinstance(v, list) else v
            for k, v in json.loads(str(data["spec"])).items()
        }
    )
    model = CalibrationModel(robot, spec)
    x0, free = data["x0"], data["free"]
    w = Weights(data["sigma"])
    payload = float(data["payload"]) if data["payload"] > 0 else None
    x = fd_fit(model, x0, free, meas, w, meas.model_inputs(payload), x_scale)
    np.save(out, x)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
