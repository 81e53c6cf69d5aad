"""Shared fixtures: a seeded random generator (never global np.random), the CLI run in a
subprocess, as a user would, the model's Jacobian storage poisoned with NaN, and the
choice of the model's code (compiled kernel or numpy)."""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest


@pytest.fixture(autouse=True)
def _poisoned_jacobian_storage(monkeypatch: pytest.MonkeyPatch) -> None:
    """The model's Jacobian starts uninitialised (np.empty); here it starts as NaN, so an
    entry that evaluate() forgets to write fails every test that reads it (FD checks,
    fits) instead of passing on memory that happened to be zero."""
    from kinecal.models import _model

    monkeypatch.setattr(_model, "_alloc", lambda shape: np.full(shape, np.nan))


def require_compiled_kernel() -> None:
    """Skip a test of the compiled kernel where it is not built (an installation without
    a C compiler), unless KINECAL_REQUIRE_KERNEL=1 (CI) makes that a failure."""
    from kinecal.models import compiled_kernel_available

    if compiled_kernel_available():
        return
    if os.environ.get("KINECAL_REQUIRE_KERNEL") == "1":
        pytest.fail("the compiled kernel is not built, and KINECAL_REQUIRE_KERNEL=1")
    pytest.skip("the compiled kernel is not built (no C compiler at install time)")


@pytest.fixture(params=["c", "numpy"])
def kernel(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> str:
    """Run the test with the compiled kernel, then with the numpy code."""
    if request.param == "c":
        require_compiled_kernel()
    monkeypatch.setenv("KINECAL_KERNEL", request.param)
    return str(request.param)


@pytest.fixture
def numpy_kernel(monkeypatch: pytest.MonkeyPatch) -> None:
    """The model's numpy code, for tests of what only it has (the kept forward state)."""
    monkeypatch.setenv("KINECAL_KERNEL", "numpy")


@pytest.fixture
def one_blas_thread() -> Iterator[None]:
    """This process on one BLAS thread, as kinecal's worker processes are (and the
    kinecal command): serial and parallel runs then sum in the same order to the last
    digit. The previous thread count is restored."""
    from kinecal._parallel import blas_threads, set_blas_threads

    before = blas_threads()
    set_blas_threads(1)
    try:
        yield
    finally:
        if before:
            set_blas_threads(before[0])


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20240416)


def kinecal_cli(
    *args: str, cwd: str | None = None, timeout: float = 600
) -> subprocess.CompletedProcess[str]:
    """``kinecal ARGS`` in a subprocess, as a user runs it."""
    return subprocess.run(
        [sys.executable, "-m", "kinecal", *args],
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=timeout,
    )


@pytest.fixture
def run_cli() -> Callable[..., subprocess.CompletedProcess[str]]:
    return kinecal_cli


@pytest.fixture
def run_cli_here(
    capsys: pytest.CaptureFixture[str],
) -> Callable[..., subprocess.CompletedProcess[str]]:
    """``kinecal ARGS`` in this process (:func:`kinecal.cli.main`), as ``run_cli`` gives
    it: for tests of what a command computes, prints or writes, where a new interpreter
    adds only its start-up time."""
    from tests.cli_contract import run_kinecal

    def run(*args: str, **_: object) -> subprocess.CompletedProcess[str]:
        res = run_kinecal(capsys, *map(str, args))
        return subprocess.CompletedProcess(list(args), res.code, res.out, res.err)

    return run


# Work units of `make test` on pytest-xdist workers (--dist loadgroup): one per test, but
# a module below runs whole on one worker, so its module and session fixtures (0.3-2 s
# each) are built once, not on each worker; modules of one group share session fixtures.
# (xdist_group marks would do it per test, but pytest-xdist 3.8 loses them on pytest 9.)
SHARED_MODULES = {
    "tests/cli/test_workflow_cli.py": "cli-exp1",  # exp2_files, calibrated_exp1
    "tests/io/test_issue_19_serialisation.py": "cli-exp1",
    # exp2_exact, exp1_exact, simulated_exp2 (issue 25 and 20), tmac
    "tests/identification/test_calibrate.py": "identification",
    "tests/identification/test_identifiability.py": "identification",
    "tests/identification/test_issue_25_robust.py": "identification",
    "tests/identification/test_issue_26_blocks.py": "identification",
    "tests/identification/test_issue_4_accuracy.py": "identification",
    "tests/identification/test_lift.py": "identification",
    "tests/identification/test_pipeline.py": "identification",
    "tests/identification/test_robustness.py": "identification",
    "tests/identification/test_select.py": "identification",
    "tests/identification/test_issue_20_sessions.py": "identification",
    "tests/compensation/test_compensate.py": "compensation",  # tracker_twin, twin
    "tests/compensation/test_issue_23_ik.py": "compensation",
    "tests/compensation/test_issue_23_programs.py": "compensation",
    "tests/compensation/test_issue_26_chunks.py": "compensation",
    "tests/compensation/test_issue_34_cartesian.py": "compensation",
    "tests/compensation/test_issue_34_singular.py": "compensation",
    "tests/fuzz/test_fuzz_csv.py": "fuzz",  # point_data
    "tests/fuzz/test_fuzz_model.py": "fuzz",
    "tests/fuzz/test_fuzz_robot.py": "fuzz",
    "tests/sensor/test_calibration.py": "sensor-boards",
    "tests/planning/test_plan.py": "planning-twin",
    "tests/report/test_report_cli.py": "report-result",
    "tests/report/test_html_report.py": "report-twin",
    "tests/io/test_issue_20_cli.py": "sensor-model",
    "tests/io/test_model_file.py": "model-result",
    "tests/cli/test_plan_cli.py": "plan-files",
    "tests/cli/test_export_cli.py": "export-models",
    "tests/cli/test_issue_34_urdf_like.py": "urdf-like",
    "tests/robot/test_issue_35_urdf_mimic.py": "urdf-mimic",
    "tests/cli/test_fault_inputs.py": "fault-inputs",
    "tests/cli/test_fault_results.py": "fault-results",
    "tests/faults/test_overwrite_inputs.py": "faults",  # data (tests/faults/conftest)
    "tests/faults/test_model_file_bounds.py": "faults",
    "tests/faults/test_kinds_and_weights.py": "faults",
    "tests/faults/test_full_disk.py": "faults",
    "tests/faults/test_audit_bad_files.py": "faults",
    "tests/faults/test_round_trips.py": "round-trips",  # written (every writer once)
    "tests/faults/test_images.py": "faults-scan",
    "tests/identification/test_issue_26_auto.py": "poses-300",
    "tests/test_package_structure.py": "import-graph",
    "tests/slow/test_sensor_end_to_end.py": "slow-sensor",  # calibrated_sensor
    "tests/slow/test_sensor_feeds_identification.py": "slow-sensor",
}


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config: pytest.Config, log: object) -> object:
    """With --dist loadgroup, the groups above."""
    if config.getvalue("dist") != "loadgroup":
        return None
    from xdist.scheduler import LoadGroupScheduling

    class Scheduling(LoadGroupScheduling):
        def _split_scope(self, nodeid: str) -> str:
            group = SHARED_MODULES.get(nodeid.split("::", 1)[0])
            return group if group else super()._split_scope(nodeid)

    return Scheduling(config, log)  # type: ignore[arg-type]


# Folders written once by the CLI and read by several tests (they write elsewhere).


@pytest.fixture(scope="session")
def simulated_exp2(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``kinecal simulate --experiment 2`` with the default seed and tracker."""
    from kinecal.cli import main

    d = tmp_path_factory.mktemp("cli-exp2") / "exp2"
    assert main(["simulate", "--experiment", "2", "--out", str(d), "-q"]) == 0
    return d


@pytest.fixture(scope="session")
def calibrated_exp1(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """``kinecal simulate --experiment 1`` (folder ``exp1``), then ``kinecal calibrate``
    of its train.csv with its targets.csv, with the report (folder ``cal``)."""
    from kinecal.cli import main

    root = tmp_path_factory.mktemp("cli-exp1")
    d, out = root / "exp1", root / "cal"
    assert main(["simulate", "--experiment", "1", "--out", str(d), "-q"]) == 0
    assert (d / "targets.csv").is_file()
    code = main([
        "calibrate",
        str(d / "train.csv"),
        "--robot",
        "fanuc-lrmate200id",
        "--targets",
        str(d / "targets.csv"),
        "--out",
        str(out),
        "-q",
    ])  # fmt: skip
    assert code == 0
    return d, out
