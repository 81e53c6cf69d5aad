"""Issue 36 benchmarks: the whole command against the scipy baseline, measured honestly.

``python -m benchmarks --issue36 [--out FILE] [--quick]`` (default FILE
``benchmarks/issue36.json``). Every time is a whole process or an in-process call with
its CPU time (user + system, of the process or its children) beside the wall time: the
VM is shared, and CPU time is what an idle core would take.

* The scipy baseline (``least_squares``, 2-point finite differences, from kinecal's own
  registered point) always runs with one BLAS thread (``OPENBLAS_NUM_THREADS=1``): with
  OpenBLAS's default of one thread per core it took 2.9x the CPU on a loaded machine,
  which flattered kinecal.
* Two data sets of 2000 poses: the main benchmark's own (experiment 2 with 5 um tracker
  noise, a subset of its test grid) and the twin as a user gets it (``kinecal simulate
  --n-train 2000``: the tracker's default noise); each with its held-out RMS.
* The whole ``kinecal calibrate --model full`` against the scipy process, run in turn
  (pairs): medians of wall and CPU time and of the pairs' CPU ratios.
* Model passes (:func:`kinecal.models.pass_counts`) of each command, run in-process.
* One pass (the compiled kernel's FK + Jacobian on one thread, then ``JᵀJ``) at 2000
  poses x 50 parameters against a floor: the FLOPs of the symmetric product ``JᵀJ``
  (m P (P + 1), m = 3 N rows) at this core's measured one-thread matrix-product rate;
  beside it the bare product ``X @ X.T`` (numpy calls BLAS dsyrk for it) and scipy's
  ``dsyrk`` on the same memory.
* A library user's ``calibrate()`` in a process whose BLAS keeps its default threads,
  against the same with one thread: CPU time of each.
* Start-up: ``python -X importtime`` of the command, kinecal's modules and the rest.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks._common import _machine, _process_env

_ONE = {"OPENBLAS_NUM_THREADS": "1"}
_ROBOT = "fanuc-lrmate200id"


def _timed(cmd: list[str], env: dict[str, str] | None = None) -> tuple[float, float]:
    """Wall and CPU seconds (user + system of the child) of one process."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    subprocess.run(cmd, check=True, capture_output=True, env=env or _process_env())
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime
    return wall, cpu


def import_times(stderr: str) -> dict[str, float]:
    """Seconds of ``python -X importtime`` output: all imports, kinecal's own modules,
    numpy, scipy, yaml, click (each module's self time summed; its package's modules
    with it)."""
    out = {"total": 0.0, "kinecal": 0.0, "numpy": 0.0, "scipy": 0.0, "yaml": 0.0}
    out["click"] = 0.0
    for line in stderr.splitlines():
        if not line.startswith("import time:") or "self [us]" in line:
            continue
        fields = line.split("|")
        if len(fields) < 3:
            continue
        self_us, name = float(fields[0].split(":")[1]), fields[2].strip()
        out["total"] += self_us * 1e-6
        top = name.split(".")[0]
        if top in out:
            out[top] += self_us * 1e-6
    return out


def jtj_floor_seconds(rows: int, cols: int, flops_per_s: float) -> float:
    """Seconds of the symmetric product ``JᵀJ`` of a (rows, cols) matrix at a rate:
    ``rows * cols * (cols + 1)`` FLOPs (one triangle, a multiply and an add each)."""
    return rows * cols * (cols + 1) / flops_per_s


def matmul_rate(n: int = 1500, repeat: int = 5) -> float:
    """This core's one-thread matrix-product rate [FLOP/s] (best of ``repeat``)."""
    from kinecal._blas import one_blas_thread

    a = np.random.default_rng(0).standard_normal((n, n))
    best = np.inf
    with one_blas_thread():
        for _ in range(repeat):
            t = time.perf_counter()
            a @ a
            best = min(best, time.perf_counter() - t)
    return 2.0 * n**3 / best


def data_sets(tmp: Path) -> dict[str, tuple[Path, Path]]:
    """``name -> (train.csv, test.csv)``: the twin as ``kinecal simulate`` writes it,
    and the main benchmark's own 2000 poses (with the rest of its grid as the test)."""
    from kinecal.io import measurements_to_csv
    from kinecal.simulation import LaserTracker, experiment2

    twin = tmp / "twin"
    subprocess.run(
        [
            sys.executable,
            "-m",
            "kinecal",
            "simulate",
            "--out",
            str(twin),
            "--n-train",
            "2000",
            "-q",
        ],
        check=True,
        capture_output=True,
        env=_process_env(),
    )
    e = experiment2(3, tracker=LaserTracker(5e-6, 0.0))
    big, robot = e.test, e.truth.robot
    perm = np.random.default_rng(1).permutation(big.n)
    own = tmp / "own"
    own.mkdir()
    (own / "train.csv").write_text(measurements_to_csv(big.subset(perm[:2000]), robot))
    (own / "test.csv").write_text(measurements_to_csv(big.subset(perm[2000:]), robot))
    return {
        "twin": (twin / "train.csv", twin / "test.csv"),
        "bench": (own / "train.csv", own / "test.csv"),
    }


def scipy_case(train: Path, case: Path) -> None:
    """The scipy baseline's start and model (kinecal's registered point, its free
    parameters and weights), as :mod:`benchmarks._scipy_fd` reads them."""
    from kinecal.identification import calibrate
    from kinecal.io import read_measurements
    from kinecal.robot import load_robot

    robot = load_robot(_ROBOT)
    meas = read_measurements(str(train), robot)
    rk = calibrate(robot, meas, "full")
    np.savez(
        case,
        spec=json.dumps(dataclasses.asdict(rk.model.spec)),
        robot=robot.name,
        x0=rk.registered,
        free=np.array([s == "estimated" for s in rk.calibrated.status]),
        sigma=rk.weights.sigma,
        payload=rk.calibrated.reference_payload_kg or 0.0,
    )


def held_out_rms(model_yaml: Path | None, x: Path | None, test: Path) -> float:
    """Held-out RMS [mm] of a model file, or of its model at the parameters ``x``."""
    from kinecal.identification import evaluate
    from kinecal.io import load_model, read_measurements

    assert model_yaml is not None
    cal = load_model(model_yaml)
    if x is not None:
        cal = dataclasses.replace(cal, params=np.load(x))
    meas = read_measurements(str(test), cal.model.robot)
    return float(evaluate(cal, meas).metrics.rms_mm)


def command_vs_scipy(
    record: Callable[..., None], name: str, train: Path, test: Path, repeat: int
) -> None:
    """The whole ``kinecal calibrate --model full --cv off`` and the scipy process in
    turn."""
    with tempfile.TemporaryDirectory() as tmp_s:
        tmp = Path(tmp_s)
        case, x_out, out = tmp / "case.npz", tmp / "x.npy", tmp / "o"
        scipy_case(train, case)
        kc = [sys.executable, "-m", "kinecal", "calibrate", str(train), "--robot"]
        # --cv off: the calibration the scipy process does (the default 5-fold
        # cross-validation, issue 38, is ten more calibrations; its own row elsewhere).
        kc += [_ROBOT, "--model", "full", "--cv", "off", "--out", str(out)]
        kc += ["--force", "-q"]
        fd = [sys.executable, "-m", "benchmarks._scipy_fd", str(case), str(train)]
        env_one = {**_process_env(), **_ONE}
        _timed(kc)  # warm-up: bytecode caches
        runs: dict[str, list[tuple[float, float]]] = {"kinecal": [], "scipy": []}
        runs["scipy_jac"] = []
        for _ in range(repeat):
            runs["kinecal"].append(_timed(kc))  # the command sets one thread itself
            runs["scipy"].append(_timed([*fd, str(x_out), "1"], env_one))
            runs["scipy_jac"].append(_timed([*fd, str(tmp / "xj.npy"), "jac"], env_one))
        rms_k = held_out_rms(out / "model.yaml", None, test)
        rms_s = held_out_rms(out / "model.yaml", x_out, test)
        rms_j = held_out_rms(out / "model.yaml", tmp / "xj.npy", test)
    med = {
        k: (statistics.median(w for w, _ in v), statistics.median(c for _, c in v))
        for k, v in runs.items()
    }
    pairs = [s[1] / k[1] for k, s in zip(runs["kinecal"], runs["scipy"])]
    record(
        f"scipy_fd_process_one_thread_2000_{name}",
        med["scipy"][0],
        "baseline: scipy least_squares (trf, its default x_scale), 2-point FD, from "
        "kinecal's registered point, one BLAS thread, whole process (CSV in)",
        cpu_seconds=med["scipy"][1],
        rms_test_mm=rms_s,
    )
    record(
        f"scipy_fd_process_one_thread_2000_{name}_xscale_jac",
        med["scipy_jac"][0],
        "the main benchmark's baseline (x_scale='jac': more iterations here), one BLAS "
        "thread",
        cpu_seconds=med["scipy_jac"][1],
        rms_test_mm=rms_j,
        cpu_speedup_of_kinecal=med["scipy_jac"][1] / med["kinecal"][1],
    )
    record(
        f"calibrate_cli_full_2000_{name}",
        med["kinecal"][0],
        ">= 3x the one-thread scipy process (its default x_scale) in CPU (moonshot 5x), "
        "equal held-out RMS",
        cpu_seconds=med["kinecal"][1],
        rms_test_mm=rms_k,
        cpu_speedup=med["scipy"][1] / med["kinecal"][1],
        cpu_speedup_pairs_median=statistics.median(pairs),
        cpu_speedup_pairs_range=[min(pairs), max(pairs)],
        wall_speedup=med["scipy"][0] / med["kinecal"][0],
        load_average=os.getloadavg()[0],
    )


def passes_per_command(record: Callable[..., None], train: Path, test: Path) -> None:
    """Model passes of each command on the twin's 2000 poses (in-process, serial): the
    default command (``--model auto`` with its 5-fold cross-validation, one worker so
    every pass is counted here) and ``--model full --cv off``, the calibration with its
    rejection and nominal check alone."""
    from kinecal.cli import main
    from kinecal.models import pass_counts

    with tempfile.TemporaryDirectory() as tmp_s:
        out = Path(tmp_s)
        base = ["calibrate", str(train), "--robot", _ROBOT, "--force", "-q"]
        full = ["--model", "full", "--cv", "off"]
        # The same poses without their sigma column: the noise is estimated, and the
        # last stage refits under the new weights (its first Jacobian rescaled).
        lines = train.read_text().splitlines()
        assert lines[0].endswith(",sigma_mm")
        no_sigma = out / "no_sigma.csv"
        no_sigma.write_text("".join(ln.rsplit(",", 1)[0] + "\n" for ln in lines))
        commands = {
            "calibrate_default_serial": [*base, "--out", str(out / "a"), "--jobs", "1"],
            "calibrate_full_cv_off": [*base, *full, "--out", str(out / "f")],
            "calibrate_full_cv_off_no_sigma": [
                *base[:1],
                str(no_sigma),
                *base[2:],
                *full,
                "--out",
                str(out / "s"),
            ],
            "calibrate_full_cv_off_no_report": [
                *base,
                *full,
                "--out",
                str(out / "n"),
                "--no-report",
            ],
            "evaluate": ["evaluate", str(test), "--model", str(out / "f/model.yaml")],
        }
        for name, argv in commands.items():
            a, t, c = pass_counts(), time.perf_counter(), time.process_time()
            with (
                contextlib.redirect_stdout(io.StringIO()),
                contextlib.redirect_stderr(io.StringIO()),
            ):
                main(argv)
            wall, cpu = time.perf_counter() - t, time.process_time() - c
            b = pass_counts()
            d = {k: b[k] - a[k] for k in a}
            record(
                f"passes_{name}_2000_twin",
                wall,
                "<= ~10 Jacobian passes for the calibration (--model full --cv off)",
                cpu_seconds=cpu,
                jacobian_passes=d["jacobian"],
                forward_passes=d["forward"],
                jacobian_passes_full_size=d["jacobian_entries"] / (2000 * 50),
            )


def _pass_blocks(X: np.ndarray, poses: int = 256) -> list[np.ndarray]:
    """The rows (P, 3 N) of a point Jacobian ``X`` (columns in (component, pose)
    order) by blocks of ``poses`` poses, transposed (3 poses, P), each block
    contiguous: cache-sized pieces of the same Jacobian, as dsyrk (trans=1) takes them."""
    X3 = X.reshape(X.shape[0], 3, -1)
    return [
        np.ascontiguousarray(X3[:, :, lo : lo + poses].reshape(X.shape[0], -1)).T
        for lo in range(0, X3.shape[2], poses)
    ]


def per_pass(record: Callable[..., None], train: Path) -> None:
    """One Jacobian pass and its ``JᵀJ`` at 2000 x 50 against the floor; beside it a
    measured practical floor of ``JᵀJ``: the fastest product of the same J on this core
    (numpy's ``X @ X.T``, scipy's dsyrk, dsyrk by cache-sized blocks, and the compiled
    kernel's own products where they serve)."""
    from kinecal._blas import one_blas_thread
    from kinecal.identification import calibrate, normal_equations
    from kinecal.io import read_measurements
    from kinecal.models import _kernel, kernel_name, set_kernel_threads
    from kinecal.robot import load_robot

    robot = load_robot(_ROBOT)
    meas = read_measurements(str(train), robot)
    cal = calibrate(robot, meas, "full").calibrated
    inputs = meas.model_inputs(cal.reference_payload_kg)
    model, x = cal.model, cal.params
    out = model.evaluate(x, inputs, jacobian=True)
    assert out.J_p is not None
    cols = np.arange(model.size)
    r = out.p_user
    rate = matmul_rate()
    times: dict[str, list[float]] = {
        k: [] for k in ("kernel", "jtj", "product", "syrk", "blocks", "forward", "gram")
    }
    # CPU time of this thread beside the wall time: the VM's two cores are shared.
    cpu: dict[str, list[float]] = {"kernel": [], "jtj": []}
    # The bare product numpy's matmul forms (it calls BLAS dsyrk for X @ X.T),
    # scipy's dsyrk on the same memory (Fortran order, one triangle), and dsyrk summed
    # over blocks of 256 poses (each block contiguous and cache-sized): the same work.
    from scipy.linalg.blas import dsyrk

    X = out.J_p.transpose(2, 1, 0).reshape(model.size, -1)
    blocks = _pass_blocks(X)
    set_kernel_threads(1)
    try:
        with one_blas_thread():
            for _ in range(50):
                t, c = time.perf_counter(), time.thread_time()
                model.evaluate(x, inputs, jacobian=True)
                times["kernel"].append(time.perf_counter() - t)
                cpu["kernel"].append(time.thread_time() - c)
                t, c = time.perf_counter(), time.thread_time()
                normal_equations(r, out.J_p, cols, np.ones(model.size))
                times["jtj"].append(time.perf_counter() - t)
                cpu["jtj"].append(time.thread_time() - c)
                t = time.perf_counter()
                X @ X.T
                times["product"].append(time.perf_counter() - t)
                t = time.perf_counter()
                dsyrk(1.0, X.T, trans=1)
                times["syrk"].append(time.perf_counter() - t)
                t = time.perf_counter()
                A = np.zeros((model.size, model.size), order="F")
                for B in blocks:
                    A = dsyrk(1.0, B, trans=1, beta=1.0, c=A, overwrite_c=1)
                times["blocks"].append(time.perf_counter() - t)
                t = time.perf_counter()
                model.evaluate(x, inputs)
                times["forward"].append(time.perf_counter() - t)
                t = time.perf_counter()
                gram = _kernel.gram(out.J_p, r, 0, model.size, None)  # None: BLAS
                times["gram"].append(
                    time.perf_counter() - t if gram is not None else 1.0
                )
    finally:
        set_kernel_threads(None)
    kernel, jtj, product, syrk, by_blocks, forward, gram_s = (
        statistics.median(v) for v in times.values()
    )
    kernel_cpu, jtj_cpu = (statistics.median(v) for v in cpu.values())
    floor = jtj_floor_seconds(3 * meas.n, model.size, rate)
    practical = min(product, syrk, by_blocks, gram_s)
    record(
        "pass_2000x50_one_thread",
        kernel + jtj,
        "within 2x of the floor (kernel and JᵀJ)",
        kernel_seconds=kernel,
        kernel_forward_only_seconds=forward,
        jtj_seconds=jtj,
        jtj_product_seconds=product,
        jtj_scipy_dsyrk_seconds=syrk,
        jtj_dsyrk_256_pose_blocks_seconds=by_blocks,
        jtj_compiled_gram_seconds=gram_s if gram_s < 1.0 else None,
        floor_seconds=floor,
        floor_flops=3 * meas.n * model.size * (model.size + 1),
        matmul_gflops=rate / 1e9,
        ratio_to_floor=(kernel + jtj) / floor,
        kernel_cpu_seconds=kernel_cpu,
        jtj_cpu_seconds=jtj_cpu,
        cpu_ratio_to_floor=(kernel_cpu + jtj_cpu) / floor,
        # Poses per vector of the compiled kernel (the widest the CPU runs).
        kernel_lanes=_kernel._ckernel.lanes()
        if hasattr(_kernel._ckernel, "lanes")
        else None,
        load_average=os.getloadavg()[0],
        jtj_ratio_to_floor=jtj / floor,
        # Not the target: the fastest measured JᵀJ of the same J on this core.
        jtj_practical_floor_seconds=practical,
        practical_floor_ratio_to_floor=practical / floor,
        ratio_to_practical_floor=(kernel + jtj) / practical,
        code=kernel_name(model),
    )


_LIBRARY = """
import sys, time
from kinecal.identification import calibrate
from kinecal.io import read_measurements
from kinecal.robot import load_robot
robot = load_robot("fanuc-lrmate200id")
meas = read_measurements(sys.argv[1], robot)
calibrate(robot, meas, "full")
c = time.process_time()
for _ in range(3):
    calibrate(robot, meas, "full")
print((time.process_time() - c) / 3)
"""


def library_threads(record: Callable[..., None], train: Path) -> None:
    """A library user's calibrate() with the BLAS's default threads and with one."""
    env = _process_env()
    default = {k: v for k, v in env.items() if k != "OPENBLAS_NUM_THREADS"}
    cpu = {}
    for name, e in (("default", default), ("one", {**env, **_ONE})):
        out = subprocess.run(
            [sys.executable, "-c", _LIBRARY, str(train)],
            check=True,
            capture_output=True,
            text=True,
            env=e,
        )
        cpu[name] = float(out.stdout.split()[-1])
    record(
        "library_calibrate_2000_default_blas_threads_cpu",
        cpu["default"],
        "the same CPU as with one BLAS thread (the library limits them itself)",
        one_thread_cpu_seconds=cpu["one"],
        ratio=cpu["default"] / cpu["one"],
        load_average=os.getloadavg()[0],
    )


def startup(record: Callable[..., None], train: Path) -> None:
    """``python -X importtime`` of the whole command (no report) and of ``--help``."""
    with tempfile.TemporaryDirectory() as tmp:
        for name, argv in (
            (
                "calibrate_no_report",
                [
                    "calibrate",
                    str(train),
                    "--robot",
                    _ROBOT,
                    "--out",
                    tmp,
                    "--force",
                    "-q",
                    "--no-report",
                ],
            ),
            (
                "calibrate",
                [
                    "calibrate",
                    str(train),
                    "--robot",
                    _ROBOT,
                    "--out",
                    tmp,
                    "--force",
                    "-q",
                ],
            ),
        ):
            cmd = [sys.executable, "-X", "importtime", "-m", "kinecal", *argv]
            runs = []
            for _ in range(3):
                r = subprocess.run(
                    cmd, capture_output=True, text=True, env=_process_env()
                )
                runs.append(import_times(r.stderr))
            med = {k: statistics.median(r[k] for r in runs) for k in runs[0]}
            record(
                f"imports_{name}_2000_twin",
                med["total"],
                "import only what a run uses",
                **{f"{k}_seconds": v for k, v in med.items() if k != "total"},
            )


def large_from_csv(record: Callable[..., None], n: int = 10**6) -> None:
    """``kinecal calibrate --model full`` on ``n`` simulated tracker poses from a CSV
    file, with its report, as a user runs it: CPU, wall and peak RSS of the process."""
    from benchmarks._large import simulate
    from kinecal.identification import Measurements
    from kinecal.io import measurements_to_csv
    from kinecal.robot import load_robot

    with tempfile.TemporaryDirectory() as tmp_s:
        tmp = Path(tmp_s)
        simulate(n, tmp / "poses.npz")
        data = np.load(tmp / "poses.npz")
        meas = Measurements("point", data["q"], data["p"], sigma=data["sigma"])
        (tmp / "poses.csv").write_text(measurements_to_csv(meas, load_robot(_ROBOT)))
        del meas, data
        cmd = [sys.executable, "-m", "kinecal", "calibrate", str(tmp / "poses.csv")]
        cmd += ["--robot", _ROBOT, "--model", "full", "--out", str(tmp / "o"), "-q"]
        wall, cpu = _timed(cmd)
        peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    record(
        f"calibrate_cli_full_{n:.0e}_csv".replace("+0", ""),
        wall,
        "1e6 poses from CSV with the report: < 60 s CPU, < 2 GB",
        cpu_seconds=cpu,
        peak_rss_mb=peak,
        load_average=os.getloadavg()[0],
    )


def main(
    out_path: str, quick: bool = False, large: bool = False, sensor: bool = False
) -> int:
    """Every issue-36 row, written to ``out_path`` (JSON); with ``large`` only the 1e6
    row, with ``sensor`` only the sensor scan's rows, merged into the file's other
    rows."""
    results: dict[str, dict[str, Any]] = {}

    def record(name: str, seconds: float, target: str, **extra: Any) -> None:
        results[name] = {"seconds": float(seconds), "target": target, **extra}
        shown = {
            k: round(v, 4) if isinstance(v, float) else v for k, v in extra.items()
        }
        print(f"  {name:46s} {seconds:8.4f} s  {shown}", flush=True)

    print("kinecal issue-36 benchmarks", json.dumps(_machine()), flush=True)
    path = Path(out_path)
    if large or sensor:
        old = json.loads(path.read_text()) if path.is_file() else {}
        results.update(old.get("results", {}))
        if large:
            large_from_csv(record)
        if sensor:
            from benchmarks._sensor_scan import sensor_scan

            sensor_scan(record, _timed, 3 if quick else 7)
        old["results"] = results
        old.setdefault("machine", _machine())
        tmp_out = path.with_suffix(".tmp")
        tmp_out.write_text(json.dumps(old, indent=2) + "\n")
        os.replace(tmp_out, path)
        print(f"-> {path}")
        return 0
    repeat = 3 if quick else 7
    with tempfile.TemporaryDirectory() as tmp:
        sets = data_sets(Path(tmp))
        for name, (train, test) in sets.items():
            command_vs_scipy(record, name, train, test, repeat)
        twin_train, twin_test = sets["twin"]
        passes_per_command(record, twin_train, twin_test)
        per_pass(record, twin_train)
        library_threads(record, twin_train)
        startup(record, twin_train)
    out = {
        "machine": _machine(),
        "results": results,
        "created_unix": time.time(),
        "repeats": repeat,
    }
    tmp_out = path.with_suffix(".tmp")
    tmp_out.write_text(json.dumps(out, indent=2) + "\n")
    os.replace(tmp_out, path)
    print(f"-> {path}")
    return 0
