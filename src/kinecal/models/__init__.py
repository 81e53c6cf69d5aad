"""Models: parameter layout, unified kinematic model (Eq. 6-10), compliance (Eq. 11-26).

Each name loads its module on first use (:mod:`kinecal._lazy`).
"""

from typing import TYPE_CHECKING

from kinecal import _lazy

if TYPE_CHECKING:
    from kinecal._cpu import set_kernel_threads
    from kinecal.models._chain import ChainFrames, chain_frames
    from kinecal.models._compliance import (
        link_torque_basis,
        load_torques,
        ntm_basis,
        ntm_names,
    )
    from kinecal.models._definition import ModelDefinition
    from kinecal.models._ik import IKResult, solve_ik
    from kinecal.models._ik_lm import solve_ik_lm
    from kinecal.models._inputs import ModelInputs
    from kinecal.models._kernel import compiled_kernel_available, kernel_status
    from kinecal.models._layout import KINDS, ParameterLayout, ParamKind, ParamSpec
    from kinecal.models._model import (
        CalibrationModel,
        ModelOutput,
        kernel_name,
        pass_counts,
    )
    from kinecal.models._numpy_forward import ForwardState
    from kinecal.models._spec import PRESETS, ModelSpec, parallel_pairs

__all__ = [
    "KINDS",
    "PRESETS",
    "CalibrationModel",
    "ChainFrames",
    "ForwardState",
    "IKResult",
    "ModelDefinition",
    "ModelInputs",
    "ModelOutput",
    "ModelSpec",
    "ParamKind",
    "ParamSpec",
    "ParameterLayout",
    "chain_frames",
    "compiled_kernel_available",
    "kernel_name",
    "kernel_status",
    "link_torque_basis",
    "load_torques",
    "ntm_basis",
    "ntm_names",
    "parallel_pairs",
    "pass_counts",
    "set_kernel_threads",
    "solve_ik",
    "solve_ik_lm",
]

__getattr__, __dir__ = _lazy.exports(
    __name__,
    {
        "kinecal._cpu": ("set_kernel_threads",),
        "_chain": ("ChainFrames", "chain_frames"),
        "_compliance": ("link_torque_basis", "load_torques", "ntm_basis", "ntm_names"),
        "_definition": ("ModelDefinition",),
        "_ik": ("IKResult", "solve_ik"),
        "_ik_lm": ("solve_ik_lm",),
        "_inputs": ("ModelInputs",),
        "_kernel": ("compiled_kernel_available", "kernel_status"),
        "_layout": ("KINDS", "ParameterLayout", "ParamKind", "ParamSpec"),
        "_model": (
            "CalibrationModel",
            "ModelOutput",
            "kernel_name",
            "pass_counts",
        ),
        "_numpy_forward": ("ForwardState",),
        "_spec": ("PRESETS", "ModelSpec", "parallel_pairs"),
    },
)
