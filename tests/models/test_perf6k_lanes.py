"""The compiled kernel's vector widths (``_ckernel.lanes``: 2 poses a vector, 4 with
AVX2, 8 with AVX-512F) give the same numbers, to the last bit, on every kind of term."""

from __future__ import annotations

import platform
from pathlib import Path

import numpy as np
import pytest

from kinecal.models import (
    CalibrationModel,
    ModelInputs,
    ModelSpec,
    _kernel,
    set_kernel_threads,
)
from kinecal.robot import load_robot
from tests.conftest import require_compiled_kernel

# Several user frames and markers, the cam rotation (a sensor's pose data), payload and
# link compliance with bodies, Fourier terms and a Hayati row: every branch of the kernel.
SPEC = ModelSpec(
    cam_rotation=True,
    hayati=(2,),
    ntm_joints=(1, 2, 3, 5),
    ntm_order=2,
    load=True,
    link="paper",
    link_bodies=(2, 3, 5),
    sets=("a", "b", "c"),
    markers=("m", "n"),
)


@pytest.fixture
def ck():
    """The compiled module, its width restored afterwards."""
    require_compiled_kernel()
    mod = _kernel._ckernel
    before = mod.lanes()
    yield mod
    mod.lanes(before)


def _widths(mod) -> list[int]:
    out = []
    for n in (1, 2, 4, 8):
        try:
            mod.lanes(n)
        except ValueError:
            continue
        out.append(n)
    return out


def _case(n_poses: int, seed: int = 3):
    rng = np.random.default_rng(seed)
    robot = load_robot("fanuc-lrmate200id")
    model = CalibrationModel(robot, SPEC)
    lim = np.clip(robot.limits, -3.0, 3.0)
    inputs = ModelInputs.make(
        rng.uniform(lim[:, 0], lim[:, 1], size=(n_poses, robot.n_joints)),
        set_index=rng.integers(0, 3, n_poses),
        marker_index=rng.integers(0, 2, n_poses),
        p_cam=rng.normal(size=(n_poses, 3)) * 0.1,
        load_scale=rng.uniform(0.5, 1.5, n_poses),
    )
    p = model.nominal + rng.normal(size=model.size) * model.layout.scales * 3
    for i, s in enumerate(model.layout.specs):
        if s.kind == "compliance":
            p[i] = rng.normal() * 1e-3
        elif s.kind == "ntm":
            p[i] = rng.normal() * 1e-3
        elif s.kind in ("moment", "ratio"):
            p[i] = 0.3 + 0.1 * rng.normal()
    return model, p, inputs


def _outputs(model, p, inputs) -> list[np.ndarray]:
    out = model.evaluate(p, inputs, orientation=True, jacobian=True, products=True)
    assert out.J_p is not None and out.J_w is not None and out.R_user_cam is not None
    return [out.p_user, out.R_user_cam, out.J_p, out.J_w, out.theta]


def test_every_width_gives_the_same_numbers(ck, monkeypatch):
    """An odd number of poses (a partial last block on every width), one thread."""
    monkeypatch.setenv("KINECAL_KERNEL", "c")
    model, p, inputs = _case(1003)
    widths = _widths(ck)
    assert widths
    set_kernel_threads(1)
    try:
        results = {}
        for n in widths:
            ck.lanes(n)
            results[n] = _outputs(model, p, inputs)
    finally:
        set_kernel_threads(None)
    base = results[widths[0]]
    assert np.isfinite(base[2]).all()
    for n in widths[1:]:
        for a, b in zip(results[n], base):
            np.testing.assert_array_equal(a, b, err_msg=f"{n} lanes")


def test_the_widest_width_splits_over_threads_alike(ck, monkeypatch):
    """Threads take whole blocks of the width in use; their parts give the same
    numbers as one thread."""
    monkeypatch.setenv("KINECAL_KERNEL", "c")
    model, p, inputs = _case(3 * _kernel._MIN_POSES_PER_THREAD + 5)
    ck.lanes(max(_widths(ck)))
    try:
        set_kernel_threads(3)
        threaded = _outputs(model, p, inputs)
        set_kernel_threads(1)
        serial = _outputs(model, p, inputs)
    finally:
        set_kernel_threads(None)
    for a, b in zip(threaded, serial):
        np.testing.assert_array_equal(a, b)


def test_the_widest_width_the_cpu_runs_is_chosen(ck):
    """The widths built (GCC on x86-64: 4 lanes of AVX2 and 8 of AVX-512F beside the
    baseline's 2) run where the CPU has their instructions, and the widest is the
    default."""
    default = ck.lanes()
    widths = _widths(ck)
    assert default == max(widths)
    assert set(widths) <= set(ck.WIDTHS)
    cpuinfo = Path("/proc/cpuinfo")
    if platform.machine() != "x86_64" or not cpuinfo.is_file():
        pytest.skip("the CPU's features are read from Linux's /proc/cpuinfo on x86-64")
    # setuptools builds with Python's compiler; -DKINECAL_SCALAR_KERNEL: one lane only.
    if "GCC" in platform.python_compiler() and ck.WIDTHS != (1,):
        assert {2, 4, 8} <= set(ck.WIDTHS)
    flags = set(cpuinfo.read_text().split())
    for lanes, flag in ((4, "avx2"), (8, "avx512f")):
        if lanes in ck.WIDTHS:
            assert (flag in flags) == (lanes in widths), flag


def test_an_unknown_width_is_refused(ck):
    with pytest.raises(ValueError, match="3 lanes not available"):
        ck.lanes(3)
