"""The sections of ``python -m benchmarks`` (the main run): the model kernel, the
calibration against scipy's finite-difference fit in-process and as whole processes,
the default cross-validation (issue 38), the fixed-step and ``--model auto`` baselines,
compensation, the sensor, CSV files and start-up. Each records its rows in a
:class:`Bench`."""

from __future__ import annotations

import json
import resource
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks._common import (
    _median_time,
    _model_code,
    _process_env,
    _run,
)


def _jacobian_instructions(
    model: Any, params: Any, inputs: Any, code: str
) -> float | None:
    """Instructions per FK + Jacobian evaluation by ``code`` ('c' on one thread, or
    'numpy'; callgrind; None without valgrind or for inputs with several sets or
    markers, which the helper does not rebuild)."""
    import dataclasses
    import shutil
    import tempfile

    several = len(set(inputs.set_index)) > 1 or len(set(inputs.marker_index)) > 1
    if shutil.which("valgrind") is None or several:
        return None
    with tempfile.TemporaryDirectory() as tmp:
        path = str(Path(tmp) / "case.npz")
        np.savez(
            path,
            spec=json.dumps(dataclasses.asdict(model.spec)),
            robot=model.robot.name,
            params=params,
            q_ctrl=inputs.q_ctrl,
            p_cam=inputs.p_cam,
            load_scale=inputs.load_scale,
        )
        env = {**_process_env(), "OPENBLAS_NUM_THREADS": "1", "KINECAL_KERNEL": code}
        # A plain run first, so both counted runs load the same bytecode caches.
        helper = [sys.executable, "-m", "benchmarks._instructions", path]
        subprocess.run([*helper, "0"], check=True, capture_output=True, env=env)
        counts = []
        for k in (0, 4):
            out = str(Path(tmp) / f"callgrind.{k}")
            cmd = ["valgrind", "--tool=callgrind", f"--callgrind-out-file={out}"]
            cmd += [*helper, str(k)]
            r = subprocess.run(cmd, capture_output=True, text=True, env=env)
            found = [ln for ln in r.stderr.splitlines() if "Collected :" in ln]
            if r.returncode != 0 or not found:
                return None
            counts.append(int(found[-1].split(":")[-1].replace(",", "")))
    return (counts[1] - counts[0]) / 4


@dataclass
class Bench:
    """Repeats and the results table shared by the benchmark sections."""

    rep: int
    rep_fast: int
    results: dict[str, dict[str, Any]] = field(default_factory=dict)

    def record(self, name: str, seconds: float, target: str, **extra: Any) -> None:
        best = getattr(seconds, "best", seconds)
        self.results[name] = {
            "seconds": float(seconds),
            "best_seconds": float(best),
            "target": target,
            **extra,
        }
        print(f"  {name:38s} {seconds * 1e3:10.2f} ms   ({target})", flush=True)


@dataclass
class Fit:
    """The 2000-pose calibration the scipy baselines start from (section 3)."""

    sub: Any
    test: Any
    rk: Any
    model: Any
    free: np.ndarray
    x0: np.ndarray
    w: Any
    inp: Any
    t_k: float
    t_fd: float


def kernel_cases(b: Bench, e: Any) -> tuple[Any, str]:
    """1. FK + parameter Jacobian of the full model; 1b. plain FK."""
    from kinecal.identification import calibrate

    rep_fast, record, results = b.rep_fast, b.record, b.results
    big, robot = e.test, e.truth.robot  # ~6900 poses

    res100 = calibrate(robot, e.train, "full")
    cal = res100.calibrated
    inputs = big.model_inputs(cal.reference_payload_kg)

    def jac() -> object:
        return cal.model.evaluate(cal.params, inputs, jacobian=True)

    from kinecal.models import kernel_name, set_kernel_threads

    code = kernel_name(cal.model)  # 'c' where the compiled kernel is built
    # First with the C library's default allocator (a library user who has not called
    # kinecal.keep_freed_memory()), then with the setting the kinecal command applies.
    t, _ = _median_time(jac, rep_fast)
    record("fk_jacobian_full_default_malloc", t, "library default", poses=big.n)
    t, _ = _median_time(lambda: calibrate(robot, big, "full"), 1)
    record("calibrate_full_7000_default_malloc", t, "library default", poses=big.n)
    from kinecal import keep_freed_memory

    keep_freed_memory()
    t, _ = _median_time(jac, rep_fast)
    record(
        "fk_jacobian_full",
        t,
        "<= 10 ms for 7000 poses",
        poses=big.n,
        parameters=cal.model.size,
        code=code,
    )
    if code == "c":  # the compiled kernel on one thread, and the numpy code
        set_kernel_threads(1)
        t, _ = _median_time(jac, rep_fast)
        set_kernel_threads(None)
        record("fk_jacobian_full_one_thread", t, "compiled kernel, one thread")
        with _model_code("numpy"):
            t, _ = _median_time(jac, rep_fast)
        record("fk_jacobian_full_numpy", t, "the numpy code (no compiler)")
    # The same on a new inputs object each time: what the quantities of the poses alone
    # (kept per inputs object, as every solver iteration reuses them) cost on top.
    t, _ = _median_time(
        lambda: cal.model.evaluate(
            cal.params,
            type(inputs).make(
                inputs.q_ctrl, p_cam=inputs.p_cam, load_scale=inputs.load_scale
            ),
            jacobian=True,
        ),
        rep_fast,
    )
    record("fk_jacobian_full_new_inputs", t, "first evaluation of new poses")
    for c in ("c", "numpy") if code == "c" else ("numpy",):
        instructions = _jacobian_instructions(cal.model, cal.params, inputs, c)
        if instructions is not None:
            key = "fk_jacobian_full_instructions" + ("_numpy" if c == "numpy" else "")
            results[key] = {
                "instructions": instructions,
                "target": "deterministic (callgrind): compares code, not machines",
                "code": c,
            }
            print(f"  {key:38s} {instructions / 1e6:10.2f} M")

    # 1b. plain FK (nominal kinematic model) and the full model without Jacobians
    from kinecal.simulation import planning_model

    pm, x_nom = planning_model(e.truth)
    inp_nom = big.model_inputs()
    t_fk, _ = _median_time(lambda: pm.evaluate(x_nom, inp_nom), rep_fast)
    record("fk_plain_7000", t_fk, "vectorised, no loop over poses", poses=big.n)
    t_full, _ = _median_time(lambda: cal.model.evaluate(cal.params, inputs), rep_fast)
    record("fk_full_model_7000", t_full, "< 3x plain FK", ratio=t_full / t_fk)

    return cal, code


def calibration_cases(b: Bench, e: Any, code: str) -> None:
    """2. calibrate, all three stages, ~7000 poses, in-process."""
    from kinecal.identification import calibrate

    rep, record, big, robot = b.rep, b.record, e.test, e.truth.robot
    t, r7 = _median_time(lambda: calibrate(robot, big, "full"), max(rep // 2, 1))
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    record(
        "calibrate_full_7000",
        t,
        "<= 1 s",
        poses=big.n,
        rms_mm=r7.metrics_after.rms_mm,
        peak_rss_mb=peak_mb,
        stage_iterations={st.name: st.iterations for st in r7.stages},
        code=code,
    )
    if code == "c":
        with _model_code("numpy"):
            t, _ = _median_time(lambda: calibrate(robot, big, "full"), max(rep // 2, 1))
        record("calibrate_full_7000_numpy", t, "the numpy code (no compiler)")


def scipy_cases(b: Bench, e: Any) -> Fit:
    """3. 2000 poses: kinecal against scipy least_squares with finite differences."""
    from dataclasses import replace

    from kinecal.identification import calibrate, evaluate

    rep, record, big, robot = b.rep, b.record, e.test, e.truth.robot
    perm = np.random.default_rng(1).permutation(big.n)  # a representative subset
    sub = big.subset(perm[:2000])
    t_k, rk = _median_time(lambda: calibrate(robot, sub, "full"), max(rep // 2, 1))
    test = big.subset(perm[2000:])
    rms_k = evaluate(rk.calibrated, test).metrics.rms_mm
    model = rk.calibrated.model
    free = np.array([s == "estimated" for s in rk.calibrated.status])
    x0 = rk.registered.copy()
    w = rk.weights
    inp = sub.model_inputs(rk.calibrated.reference_payload_kg)

    from benchmarks._scipy_fd import fd_fit

    t_fd, x_fd = _median_time(lambda: fd_fit(model, x0, free, sub, w, inp), 1)
    rms_fd = evaluate(replace(rk.calibrated, params=x_fd), test).metrics.rms_mm
    record("calibrate_full_2000", t_k, ">= 5x faster than scipy FD", rms_test_mm=rms_k)
    record(
        "scipy_least_squares_fd_2000",
        t_fd,
        "baseline",
        rms_test_mm=rms_fd,
        speedup=t_fd / t_k,
    )
    return Fit(sub, test, rk, model, free, x0, w, inp, t_k, t_fd)


def process_cases(b: Bench, e: Any, f: Fit) -> None:
    """3b. the 2000-pose fit as a whole `kinecal calibrate` process with its default
    output, against the scipy baseline in-process and as a whole process; without the
    report; the report alone."""
    from dataclasses import replace

    from kinecal.identification import evaluate

    rep, rep_fast, record, robot = b.rep, b.rep_fast, b.record, e.truth.robot
    sub, test, rk, model, x0, free, w = f.sub, f.test, f.rk, f.model, f.x0, f.free, f.w
    t_fd = f.t_fd
    import dataclasses
    import tempfile

    from kinecal.io import measurements_to_csv

    with tempfile.TemporaryDirectory() as tmp:
        csv = Path(tmp) / "poses.csv"
        csv.write_text(measurements_to_csv(sub, robot))
        cmd = [sys.executable, "-m", "kinecal", "calibrate", str(csv), "--robot"]
        cmd += ["fanuc-lrmate200id", "--model", "full", "--out", str(Path(tmp) / "o")]
        # the fit alone against scipy: without the held-out folds run by default
        cmd += ["--force", "-q", "--cv", "off"]
        _run(cmd)  # warm-up: bytecode cache
        t_cli, _ = _median_time(lambda: _run(cmd), rep)
        from kinecal.io import load_model

        rms_cli = evaluate(
            load_model(Path(tmp) / "o" / "model.yaml"), test
        ).metrics.rms_mm
        t_nr, _ = _median_time(lambda: _run([*cmd, "--no-report"]), rep)
        from kinecal.report import write_report

        out_html = Path(tmp) / "r.html"
        t_rep, _ = _median_time(
            lambda: write_report(Path(tmp) / "o", out=out_html, force=True), rep_fast
        )
        rep_cmd = [sys.executable, "-m", "kinecal", "report", str(Path(tmp) / "o")]
        rep_cmd += ["--out", str(out_html), "--force", "-q"]
        t_rep_p, _ = _median_time(lambda: _run(rep_cmd), rep)
        case = Path(tmp) / "case.npz"
        np.savez(
            case,
            spec=json.dumps(dataclasses.asdict(model.spec)),
            robot=robot.name,
            x0=x0,
            free=free,
            sigma=w.sigma,
            payload=rk.calibrated.reference_payload_kg or 0.0,
        )
        x_out = Path(tmp) / "x.npy"
        fd_cmd = [sys.executable, "-m", "benchmarks._scipy_fd", str(case), str(csv)]
        t_fdp, _ = _median_time(lambda: _run([*fd_cmd, str(x_out)]), 1)
        rms_fdp = evaluate(
            replace(rk.calibrated, params=np.load(x_out)), test
        ).metrics.rms_mm
    record(
        "scipy_least_squares_fd_2000_process",
        t_fdp,
        "baseline, as a whole process",
        rms_test_mm=rms_fdp,
    )
    record(
        "calibrate_cli_2000",
        t_cli,
        ">= 5x faster than scipy FD, as a whole process with the default HTML report",
        speedup=t_fd / t_cli,
        speedup_process_to_process=t_fdp / t_cli,
        rms_test_mm=rms_cli,
    )
    record(
        "calibrate_cli_2000_no_report",
        t_nr,
        "the same with --no-report",
        speedup_process_to_process=t_fdp / t_nr,
    )
    record("report_html_2000", t_rep, "well under 1 s (in-process, from the folder)")
    record("report_cli_2000", t_rep_p, "`kinecal report DIR` as a whole process")


def default_cv_case(b: Bench) -> None:
    """3c. issue 38: the default `kinecal calibrate` (held-out accuracy by 5-fold
    cross-validation, --model auto, the HTML report) on a `kinecal simulate` twin,
    against the same command with --cv off; alternating pairs, the median of the pairs'
    ratios beside the ratio of the medians."""
    import statistics
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        sim = Path(tmp) / "sim"
        _run([sys.executable, "-m", "kinecal", "simulate", "--out", str(sim), "-q"])
        base = [sys.executable, "-m", "kinecal", "calibrate", str(sim / "train.csv")]
        base += ["--robot", "fanuc-lrmate200id", "--out", str(Path(tmp) / "o")]
        base += ["--force", "-q"]
        _run(base)  # warm-up
        on, off, cpu_on, cpu_off = [], [], [], []
        for _ in range(max(b.rep, 11)):  # pairs: the ratio is noisy on a shared machine
            for cmd, wall, cpu in (
                (base, on, cpu_on),
                ([*base, "--cv", "off"], off, cpu_off),
            ):
                c0 = _children_cpu()
                wall.append(_median_time(lambda cmd=cmd: _run(cmd), 1)[0])
                cpu.append(_children_cpu() - c0)
    t_on, t_off = statistics.median(on), statistics.median(off)
    b.record(
        "calibrate_default_cv_twin",
        t_on,
        "<= 1.5x the same command with --cv off (issue 38)",
        cv_off_seconds=float(t_off),
        ratio_to_cv_off=float(t_on) / float(t_off),
        paired_ratio_median=statistics.median(
            float(a) / float(c) for a, c in zip(on, off, strict=True)
        ),
        paired_ratio_min_max=[
            min(float(a) / float(c) for a, c in zip(on, off, strict=True)),
            max(float(a) / float(c) for a, c in zip(on, off, strict=True)),
        ],
        pairs=len(on),
        cpu_seconds=statistics.median(cpu_on),
        cpu_off_seconds=statistics.median(cpu_off),
        paired_cpu_ratio_median=statistics.median(
            a / c for a, c in zip(cpu_on, cpu_off, strict=True)
        ),
    )


def _children_cpu() -> float:
    """User + system CPU seconds of the finished child processes so far."""
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def fixed_step_case(b: Bench, f: Fit) -> None:
    """4. the paper's fixed-step update from the same start, 200 iterations."""
    from dataclasses import replace

    from kinecal.identification import evaluate, residuals, solve_fixed_step

    record, model, sub, w, inp = b.record, f.model, f.sub, f.w, f.inp
    x0, free, rk, test = f.x0, f.free, f.rk, f.test

    def fun(x: np.ndarray, jac: bool) -> tuple[np.ndarray, np.ndarray | None]:
        blk = residuals(model, x, sub, w, inputs=inp, jacobian=jac)
        return blk.r, blk.J

    t_fs, (x_fs, costs) = _median_time(
        lambda: solve_fixed_step(fun, x0, free, n_iter=200), 1
    )
    rms_fs = evaluate(replace(rk.calibrated, params=x_fs), test).metrics.rms_mm
    record(
        "paper_fixed_step_200_iter_2000",
        t_fs,
        "baseline",
        rms_test_mm=rms_fs,
        note="zeta=0.005 removes 0.5 % of the step per iteration",
        cost_first_last=[costs[0], costs[-1]],
    )


def auto_cases(b: Bench, e: Any, f: Fit) -> None:
    """4b. --model auto on the same 2000 poses: 10 cross-validated candidate runs of 5
    folds, serially and on one worker process per CPU."""
    record, robot, sub = b.record, e.truth.robot, f.sub
    from kinecal._parallel import available_cpus
    from kinecal.identification import select_model

    cpus = available_cpus()
    t_a1, sel1 = _median_time(lambda: select_model(robot, sub, jobs=1), 1)
    t_an, seln = _median_time(lambda: select_model(robot, sub, jobs=cpus), 1)
    record("select_model_auto_2000_serial", t_a1, "baseline", chosen=sel1.spec.name)
    record(
        "select_model_auto_2000_workers",
        t_an,
        "one worker process per CPU",
        workers=cpus,
        speedup=t_a1 / t_an,
        same_choice=sel1.as_dict() == seln.as_dict(),
    )


def compensation_cases(b: Bench, e: Any, cal: Any) -> np.random.Generator:
    """5. compensation of 10,000 targets (and the compensation study's cases)."""
    from kinecal.compensation import compensate

    rep, record, big = b.rep, b.record, e.test
    rng = np.random.default_rng(0)
    q = big.q_ctrl[rng.integers(0, big.n, 10_000)]
    p_t, _ = e.truth.evaluate(q)
    q_seed = q + np.radians(0.2) * rng.standard_normal(q.shape)
    t, cr = _median_time(lambda: compensate(cal, p_t, q_seed), max(rep // 2, 1))
    record("compensate_10000", t, "<= 1 s", ok=int(np.sum(cr.status == "ok")))
    from benchmarks._compensation import compensation_cases

    compensation_cases(record, max(rep // 2, 1), _median_time)
    return rng


def sensor_cases(b: Bench, rng: np.random.Generator, quick: bool) -> None:
    """6. stripe extraction; 6b. a whole scan from files; 7. sphere fit; 7b. the
    sensor's simulated session."""
    import tempfile

    from kinecal.sensor import (
        StripeRenderer,
        extract_stripes,
        fit_sphere,
        paper_sensor,
        sphere_scene,
    )

    rep, rep_fast, record, results = b.rep, b.rep_fast, b.record, b.results
    sen = paper_sensor()
    ren = StripeRenderer(sen.camera, sen.planes)
    imgs = ren.render_scan(
        sphere_scene([0.0, 0.0, 0.14], 0.015), rng, np.arange(0, 120, 4)
    )
    t, _ = _median_time(lambda: [extract_stripes(im) for im in imgs], rep)
    record(
        "stripes_per_image",
        t / len(imgs),
        ">= 90 images/s on one core",
        images_per_s=len(imgs) / t,
    )

    # 6b. a whole scan from files: `kinecal sensor reconstruct` on 120 PNG images of
    # 1280 x 1024 (decoding, stripes on one thread per CPU, points, CSV)
    from kinecal.io import save_sensor, write_image

    scan = ren.render_scan(sphere_scene([0.0, 0.0, 0.14], 0.015), rng)
    with tempfile.TemporaryDirectory() as tmp:
        for k, im in enumerate(scan):
            write_image(Path(tmp) / f"plane_{k:03d}.png", im)
        save_sensor(Path(tmp) / "sensor.yaml", sen)
        cmd = [sys.executable, "-m", "kinecal", "sensor", "reconstruct", tmp]
        cmd += ["--sensor", str(Path(tmp) / "sensor.yaml"), "--force", "-q"]
        cmd += ["--out", str(Path(tmp) / "cloud.csv")]
        _run(cmd)  # warm-up: bytecode cache
        t, _ = _median_time(lambda: _run(cmd), max(rep // 2, 1))
    record(
        "reconstruct_scan_120_png_cli",
        t,
        "whole process, one thread per CPU",
        images=len(scan),
        images_per_s=len(scan) / t,
    )

    # 7. sphere fit of 50k points
    d = rng.normal(size=(50_000, 3))
    d[:, 2] = -np.abs(d[:, 2])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    P = np.array([0.0, 0.0, 0.14]) + d * (
        0.015 + 10e-6 * rng.standard_normal((50_000, 1))
    )
    t, _ = _median_time(lambda: fit_sphere(P), rep_fast)
    record("fit_sphere_50k", t, "<= 20 ms")

    # 7b. the sensor: simulated session, calibrations, spheres, std (issue 24)
    from benchmarks._sensor_calib import run as run_sensor

    run_sensor(record, results, rep, quick)


def file_and_startup_cases(b: Bench) -> None:
    """7c. CSV files of 1e5 and 1e6 rows; 8. CLI start-up."""
    rep, record = b.rep, b.record
    from benchmarks._csv import csv_cases

    csv_cases(record, max(rep // 3, 1))

    # 8. CLI start-up
    def start() -> None:
        _run([sys.executable, "-m", "kinecal", "--help"])

    start()  # warm-up: bytecode cache
    t, _ = _median_time(start, rep)
    record("cli_help_startup", t, "<= 0.3 s")
