"""Issue 36 point 6: ``kinecal sensor reconstruct`` of a 120-image scan against the camera.

``python -m benchmarks --issue36 --sensor`` (rows merged into ``benchmarks/issue36.json``).
A scan as the simulator writes it: 120 stripe images of a sphere (kinecal's renderer, the
paper's sensor, 1280 x 1024, 8-bit PNG). The whole command (start-up, reading and
decoding, stripe extraction, reconstruction, the cloud's CSV) as a process pinned to one
CPU, with ``--jobs 1``: CPU time (user + system) and wall time, min / median / max of the
runs, with the load average (the machine is shared). Run in turn with and without the
optional ISA-L inflation (``isal`` hidden from the process). Target: less than the
camera's 1.33 s (120 images at 90 Hz). The cloud is checked against the slow path
(OpenCV's reader, numpy.savetxt) and its sphere fit against the true sphere. An
in-process breakdown on one core: decoding alone, extraction alone.
"""

from __future__ import annotations

import io
import os
import shutil
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from benchmarks._common import _process_env

CAMERA_S = 120 / 90.0
SEED = 724_2024 + 2  # the stripe benchmark's scan (benchmarks/_stripes.py)
CENTRE = np.array([0.0021, -0.0013, 0.1387])
RADIUS = 0.015001
_NO_ISAL = (
    "import sys; sys.modules['isal'] = None; from kinecal.cli import main; "
    "sys.exit(main(sys.argv[1:]))"
)


def _scan(d: Path) -> None:
    from kinecal.io import save_sensor, write_image
    from kinecal.sensor import StripeRenderer, paper_sensor, sphere_scene

    sen = paper_sensor()
    ren = StripeRenderer(sen.camera, sen.planes)
    rng = np.random.default_rng(SEED)
    scene = sphere_scene(CENTRE, RADIUS)
    for k in range(120):
        write_image(d / f"plane_{k:03d}.png", ren.render(scene, k, rng), sync=False)
    save_sensor(d / "sensor.yaml", sen)


def _slow_path_text(d: Path) -> str:
    """The cloud's CSV text by the slow path: OpenCV's reader, numpy.savetxt."""
    from kinecal.io import image_files, load_sensor, read_image

    sen = load_sensor(d / "sensor.yaml")
    files = image_files(d, "plane_*.png")
    cloud = sen.scan([read_image(f) for f in files], jobs=1)  # type: ignore[union-attr]
    buf = io.StringIO()
    buf.write("x_mm,y_mm,z_mm,u_px,v_px,plane\n")
    data = np.column_stack([cloud.points * 1e3, cloud.uv, cloud.plane.astype(float)])
    np.savetxt(buf, data, fmt=["%.6f"] * 3 + ["%.4f"] * 2 + ["%d"], delimiter=",")
    return buf.getvalue()


def _spread(values: list[float]) -> dict[str, float]:
    return {
        "min": min(values),
        "median": statistics.median(values),
        "max": max(values),
    }


def breakdown(d: Path, repeat: int) -> dict[str, dict[str, float]]:
    """In-process on one CPU: CPU seconds of decoding the 120 files, of extracting and
    reconstructing from decoded images."""
    import cv2

    from kinecal.io import image_files, load_sensor
    from kinecal.workflows._sensor import read_scan_image as _read_scan_image

    sen = load_sensor(d / "sensor.yaml")
    files = image_files(d, "plane_*.png")
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    dec, ext = [], []
    try:
        for _ in range(repeat):
            t = time.process_time()
            imgs = [_read_scan_image(f) for f in files]
            dec.append(time.process_time() - t)
            t = time.process_time()
            sen.scan(imgs, jobs=1)  # type: ignore[union-attr]
            ext.append(time.process_time() - t)
    finally:
        cv2.setNumThreads(threads)
    return {"decode_cpu_seconds": _spread(dec), "extract_cpu_seconds": _spread(ext)}


def sensor_scan(
    record: Callable[..., None],
    timed: Callable[[list[str], dict[str, str]], tuple[float, float]],
    repeat: int,
) -> None:
    """The rows (see the module docstring)."""
    from kinecal.io import read_cloud
    from kinecal.sensor import fit_sphere

    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        _scan(d)
        args = ["sensor", "reconstruct", str(d), "--sensor", str(d / "sensor.yaml")]
        args += ["--force", "-q", "--jobs", "1"]
        pin = []
        if shutil.which("taskset") and hasattr(os, "sched_getaffinity"):
            pin = ["taskset", "-c", str(min(os.sched_getaffinity(0)))]
        env = {**_process_env(), "OPENBLAS_NUM_THREADS": "1"}
        variants = {
            "isal": [sys.executable, "-m", "kinecal"],
            "no_isal": [sys.executable, "-c", _NO_ISAL],
        }
        outs = {k: d / f"cloud_{k}.csv" for k in variants}
        for k, cmd in variants.items():  # warm-up (byte-code caches, file cache)
            timed([*pin, *cmd, *args, "--out", str(outs[k])], env)
        runs: dict[str, list[tuple[float, float]]] = {k: [] for k in variants}
        loads = [os.getloadavg()[0]]
        for _ in range(repeat):
            for k, cmd in variants.items():
                runs[k].append(timed([*pin, *cmd, *args, "--out", str(outs[k])], env))
            loads.append(os.getloadavg()[0])
        slow = _slow_path_text(d)
        same = {k: outs[k].read_text() == slow for k in variants}
        fit = fit_sphere(read_cloud(outs["isal"]))
        split = breakdown(d, max(repeat // 2, 2))
    for k in variants:
        wall = [w for w, _ in runs[k]]
        cpu = [c for _, c in runs[k]]
        record(
            f"sensor_reconstruct_120_images_one_cpu_{k}",
            statistics.median(wall),
            f"< {CAMERA_S:.2f} s CPU (the camera: 120 images at 90 Hz), the same cloud",
            cpu_seconds=statistics.median(cpu),
            cpu_seconds_range=[min(cpu), max(cpu)],
            wall_seconds_range=[min(wall), max(wall)],
            runs=len(cpu),
            load_average_range=[min(loads), max(loads)],
            cloud_same_as_slow_path=same[k],
        )
    record(
        "sensor_reconstruct_120_images_accuracy",
        0.0,
        "the sphere from the cloud: centre and radius against the truth",
        points=int(fit.inliers.size),
        inliers=int(fit.n),
        centre_error_um=float(np.linalg.norm(fit.center - CENTRE) * 1e6),
        radius_error_um=float((fit.radius - RADIUS) * 1e6),
        fit_rms_um=float(fit.rms * 1e6),
    )
    record(
        "sensor_scan_120_images_in_process_one_cpu",
        split["decode_cpu_seconds"]["median"] + split["extract_cpu_seconds"]["median"],
        "breakdown: decoding the files, extraction + reconstruction (CPU seconds)",
        **split,
        load_average=os.getloadavg()[0],
    )
