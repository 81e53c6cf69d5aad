"""Test helpers: the one finite-difference Jacobian check used by every test."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from tests.tolerances import FD_REL, FD_STEP


def fd_jacobian(
    f: Callable[[np.ndarray], np.ndarray], x: np.ndarray, h: float = FD_STEP
) -> np.ndarray:
    """Central differences of ``f`` (any output shape) w.r.t. a flat ``x``: shape (*out, n)."""
    x = np.asarray(x, dtype=np.float64)
    cols = []
    for k in range(x.size):
        e = np.zeros_like(x)
        step = h * max(1.0, abs(x[k]))
        e[k] = step
        cols.append((np.asarray(f(x + e)) - np.asarray(f(x - e))) / (2 * step))
    return np.stack(cols, axis=-1)


def assert_jacobian_matches_fd(
    J: np.ndarray,
    f: Callable[[np.ndarray], np.ndarray],
    x: np.ndarray,
    *,
    rtol: float = FD_REL,
    names: list[str] | None = None,
) -> None:
    """Assert analytic ``J`` (*out, n) equals central differences of ``f`` at ``x``.

    The error of each column is measured relative to the largest entry of the whole
    Jacobian, so columns that are legitimately tiny do not produce spurious failures.
    """
    Jfd = fd_jacobian(f, x)
    assert J.shape == Jfd.shape, (
        f"shape {J.shape} != finite-difference shape {Jfd.shape}"
    )
    scale = max(float(np.abs(Jfd).max()), 1e-12)
    err = np.abs(J - Jfd).reshape(-1, J.shape[-1]).max(axis=0) / scale
    bad = np.flatnonzero(~(err <= rtol))  # a NaN entry fails too
    if bad.size:
        labels = [names[k] if names else str(k) for k in bad]
        detail = ", ".join(f"{lab}: {err[k]:.2e}" for lab, k in zip(labels, bad))
        raise AssertionError(
            f"Jacobian columns differ from finite differences: {detail}"
        )


def exact_pose_data(truth, meas):
    """``meas`` (simulated point data) as pose data: the truth's exact tool positions
    and orientations, with sigmas of 10 um and 1e-4 rad."""
    import dataclasses

    p, R = truth.evaluate(meas.q_ctrl, orientation=True)
    return dataclasses.replace(
        meas,
        kind="pose",
        p=p,
        R_user_cam=R,
        sigma=np.full(meas.n, 1e-5),
        sigma_rot=np.full(meas.n, 1e-4),
    )


def live_processes() -> list[tuple[int, int, int]]:
    """``(pid, parent pid, process group)`` of every live process (Linux /proc; zombies
    left out), for tests that check no worker process outlives its command."""
    from pathlib import Path

    out = []
    for d in Path("/proc").glob("[0-9]*"):
        try:
            stat = (d / "stat").read_text()
        except OSError:
            continue
        fields = stat[stat.rindex(")") + 2 :].split()  # state, ppid, pgrp, ...
        if fields[0] != "Z":
            out.append((int(d.name), int(fields[1]), int(fields[2])))
    return out


def unmarked(text: str, source: str) -> str:
    """A program ``kinecal compensate`` wrote from ``source``, without the one comment
    line that marks it compensated (and FANUC's LINE_COUNT, counted up for that line,
    as in ``source``): what its bytes must equal but for the corrected numbers."""
    import re

    from kinecal.workflows._provenance import MARK

    lines = text.splitlines(keepends=True)
    kept = [ln for ln in lines if MARK not in ln]
    assert len(kept) == len(lines) - 1, "expected one provenance comment line"
    out = "".join(kept)
    count = re.search(r"^LINE_COUNT[ \t]*=[ \t]*\d+", source, re.M)
    if count is not None:
        pattern = re.compile(r"^LINE_COUNT[ \t]*=[ \t]*\d+", re.M)
        out = pattern.sub(count.group(0), out, count=1)
    return out


def kinecal_ok(capsys, *args):
    """``kinecal ARGS`` in this process (:func:`tests.cli_contract.run_kinecal`); it
    must exit 0. Its run (code, out, err)."""
    from tests.cli_contract import run_kinecal

    res = run_kinecal(capsys, *args)
    assert res.code == 0, str(res)
    return res


def calibrate_simulated(capsys, sim, out, model: str = "kinematic"):
    """``kinecal calibrate SIM/train.csv --robot SIM/robot.yaml`` (a ``simulate
    --robot`` folder) into ``out``, without cross-validation; it must exit 0."""
    return kinecal_ok(
        capsys, "calibrate", sim / "train.csv", "--robot", sim / "robot.yaml",
        "--model", model, "--cv", "off", "--out", out, "-q",
    )  # fmt: skip


def plan_lr_mate(capsys, plan, poses: int = 20):
    """``kinecal plan`` of ``poses`` LR Mate poses into ``plan`` (100 candidates, one
    random draw: fast); it must exit 0."""
    return kinecal_ok(
        capsys, "plan", "--robot", "fanuc-lrmate200id", "--poses", str(poses),
        "--out", plan, "--n-candidates", "100", "--random-draws", "1",
        "--model", "kinematic",
    )  # fmt: skip


def calibrate_args(data, robot: str, out, model: str = "kinematic") -> list[str]:
    """The arguments of ``kinecal calibrate DATA --robot ROBOT --model MODEL --out OUT``
    without a report or progress lines."""
    return ["calibrate", str(data), "--robot", robot, "--model", model,
            "--out", str(out), "--no-report", "-q"]  # fmt: skip


def perturbed_kinematic(robot, seed: int, std: float = 5e-4):
    """A calibrated kinematic model of ``robot``: its nominal parameters plus normal
    noise of ``std`` (seeded), every one 'estimated' without a covariance."""
    from kinecal.measurement import CalibratedModel
    from kinecal.models import CalibrationModel, ModelSpec

    model = CalibrationModel(robot, ModelSpec.preset("kinematic"))
    x = model.nominal + np.random.default_rng(seed).normal(0.0, std, model.size)
    return CalibratedModel(model, x, np.zeros(model.size), ["estimated"] * model.size)
