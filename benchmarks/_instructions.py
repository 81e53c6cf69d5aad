"""Instructions per evaluation, counted by valgrind's callgrind (deterministic where
wall times on a shared machine drift).

``python -m benchmarks._instructions FILE.npz K`` builds the model that FILE describes
(the environment's KINECAL_KERNEL chooses its code),
evaluates it once (imports, the inputs' kept quantities), then K more times; the
benchmarks run it under callgrind for two values of K and take the difference per
evaluation.
"""

from __future__ import annotations

import json
import sys

import numpy as np


def main(argv: list[str]) -> int:
    from kinecal.models import (
        CalibrationModel,
        ModelInputs,
        ModelSpec,
        set_kernel_threads,
    )
    from kinecal.robot import load_robot

    set_kernel_threads(1)  # the compiled kernel's count, on one thread

    path, repeats = argv[0], int(argv[1])
    data = np.load(path)
    spec = ModelSpec(
        **{
            k: tuple(v) if isinstance(v, list) else v
            for k, v in json.loads(str(data["spec"])).items()
        }
    )
    model = CalibrationModel(load_robot(str(data["robot"])), spec)
    inputs = ModelInputs.make(
        data["q_ctrl"], p_cam=data["p_cam"], load_scale=data["load_scale"]
    )
    for _ in range(repeats + 1):
        model.evaluate(data["params"], inputs, jacobian=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
