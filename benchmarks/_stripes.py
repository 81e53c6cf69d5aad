"""Stripe-extraction benchmarks (issue 24): accuracy per method, speed of a whole scan.

``python -m benchmarks --stripes [--quick] [--out FILE]`` (or as part of ``make bench``).

Accuracy: held-out stripe images of every kind (seeds and parameters the tests do not
use), 1280 x 1024: synthetic stripes with exact centres (kinecal.sensor.synthetic_stripe:
directions, curves, speckle, background gradient, reflections, a second stripe,
saturation, weak, narrow and wide stripes, 16 bit) and stripes of kinecal's renderer on
spheres with the light planes turned about the optical axis (0 to 90 deg). Methods: the
ridge detector (default), the first per-row method ('rows') and a plain grey centroid
per row. Per case: coverage of the true cross-sections, RMS and mean (bias) of the
distance along the normal, share of false centres (> 1 px off), time per image.

Speed: a whole scan of 120 PNG images (rendered, written as the simulator writes them)
read, extracted and reconstructed in-process on one core, with kinecal's PNG decoder and
with OpenCV's; and ``kinecal sensor reconstruct --jobs 1`` as a whole process pinned to
one CPU. Target: less than the camera's 1.33 s (120 images at 90 Hz).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from kinecal.sensor import (
    LightPlanes,
    StripeRenderer,
    StripeSpec,
    decode_grey_png,
    extract_stripes,
    fit_sphere,
    paper_sensor,
    score_centres,
    sphere_scene,
    sphere_stripe_truth,
    synthetic_stripe,
)

SEED = 724_2024  # held out: the tests use 0..1022
MARGIN = 8  # px: cross-sections nearer the image border are not scored
CAMERA_S = 120 / 90.0  # the camera takes a scan of 120 images at 90 Hz

METHODS: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    "ridge": lambda img: extract_stripes(img),
    "rows": lambda img: extract_stripes(img, method="rows"),
    "centroid": lambda img: plain_centroid(img),
}


def plain_centroid(img: np.ndarray, half_window: int = 8) -> np.ndarray:
    """A plain grey centroid per row (the baseline): the intensity-weighted mean column
    of the pixels within ``half_window`` of the row's maximum that are above half of it
    (over the image's median); rows whose maximum is not 10 noise levels up are left
    out. Returns (K, 2) ``u, v``."""
    f = img.astype(np.float64)
    H, W = f.shape
    bg = float(np.median(f[::8, ::8]))
    noise = 1.4826 * float(np.median(np.abs(f[::8, ::8] - bg))) or 1.0
    c = np.argmax(f, axis=1)
    rows = np.arange(H)
    peak = f[rows, c] - bg
    keep = peak > 10 * noise
    r, c, pk = rows[keep], c[keep], peak[keep]
    offs = np.arange(-half_window, half_window + 1)
    cols = np.clip(c[:, None] + offs, 0, W - 1)
    w = np.clip(f[r[:, None], cols] - bg - 0.5 * pk[:, None], 0.0, None)
    u = (w * cols).sum(axis=1) / w.sum(axis=1)
    return np.stack([u, r.astype(float)], 1)


def synthetic_cases() -> list[tuple[str, StripeSpec]]:
    """Held-out synthetic cases: sigma 1.6 px and gamma-8 speckle unless named."""
    s8 = {"sigma_px": 1.6, "speckle_k": 8.0}
    return [
        ("vertical", StripeSpec(angle_deg=3.0, center_px=(702.4, 498.0), **s8)),
        ("horizontal", StripeSpec(angle_deg=88.0, center_px=(631.0, 577.3), **s8)),
        ("30 deg", StripeSpec(angle_deg=-31.0, **s8)),
        ("60 deg", StripeSpec(angle_deg=58.0, center_px=(600.0, 480.6), **s8)),
        ("curved horizontal", StripeSpec(angle_deg=92.0, radius_px=1300.0, **s8)),
        ("curved vertical", StripeSpec(angle_deg=-4.0, radius_px=800.0, **s8)),
        ("speckle gamma-4", StripeSpec(angle_deg=12.0, sigma_px=1.6, speckle_k=4.0)),
        (
            "speckle grains 1 px",
            StripeSpec(angle_deg=-12.0, speckle_k=8.0, speckle_grain_px=1.0),
        ),
        ("no speckle", StripeSpec(angle_deg=41.0)),
        (
            "background gradient",
            StripeSpec(angle_deg=7.0, amplitude=110.0, gradient=(0.05, 0.035), **s8),
        ),
        ("reflection 5 px", StripeSpec(angle_deg=-5.0, reflection_offset_px=5.0, **s8)),
        (
            "reflection 9 px",
            StripeSpec(
                angle_deg=65.0,
                reflection_offset_px=9.0,
                reflection_rel=0.5,
                reflection_sigma_px=2.0,
                **s8,
            ),
        ),
        (
            "second stripe 80 px",
            StripeSpec(
                angle_deg=-20.0,
                reflection_offset_px=80.0,
                reflection_rel=0.6,
                reflection_sigma_px=1.6,
                **s8,
            ),
        ),
        ("saturated x2.5", StripeSpec(angle_deg=-48.0, amplitude=375.0, **s8)),
        ("saturated x6", StripeSpec(angle_deg=22.0, amplitude=900.0, **s8)),
        ("weak (amplitude 10)", StripeSpec(angle_deg=70.0, amplitude=10.0, **s8)),
        ("narrow sigma 1.0", StripeSpec(angle_deg=-70.0, sigma_px=1.0, speckle_k=8.0)),
        ("wide sigma 3.0", StripeSpec(angle_deg=28.0, sigma_px=3.0, speckle_k=8.0)),
        ("16 bit", StripeSpec(angle_deg=-84.0, bit_depth=16, **s8)),
    ]


def _turned(planes: LightPlanes, deg: float) -> LightPlanes:
    """The light planes turned by ``deg`` about the camera's optical axis."""
    a = np.radians(deg)
    R = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0, 0, 1]])
    assert planes.source is not None
    return LightPlanes(planes.n @ R.T, planes.b.copy(), R @ planes.source)


def rendered_cases(
    quick: bool,
) -> Iterator[tuple[str, np.ndarray, np.ndarray, np.ndarray]]:
    """Stripes of kinecal's renderer on a sphere, the sensor turned about its optical
    axis: (name, image, true line, its well-lit part)."""
    sen = paper_sensor()
    rng = np.random.default_rng(SEED + 1)
    c = np.array([0.0017, 0.0012, 0.1365])
    R = 0.0149
    scene = sphere_scene(c, R)
    planes_idx = (37, 83) if quick else (23, 52, 81, 104)
    for deg in (0.0, 30.0, 60.0, 90.0):
        planes = _turned(sen.planes, deg)
        ren = StripeRenderer(sen.camera, planes, speckle=0.2)
        for i in planes_idx:
            img = ren.render(scene, i, rng)
            truth = sphere_stripe_truth(sen.camera, planes, i, c, R, min_cos=0.0)
            cover = sphere_stripe_truth(sen.camera, planes, i, c, R)
            yield f"sphere, sensor turned {deg:g} deg", img, truth, cover


def _pool(scores: list[Any]) -> dict[str, float]:
    """Scores of several images of one case, pooled (images without a visible stripe,
    whose scores are NaN, left out)."""
    scores = [s for s in scores if np.isfinite(s.coverage)] or scores
    n = np.array([s.n_found for s in scores], float)
    rms = np.array([s.rms_px for s in scores])
    ok = np.isfinite(rms) & (n > 0)

    def mean(a: np.ndarray) -> float:
        return float(np.average(a[ok], weights=n[ok])) if ok.any() else float("nan")

    return {
        "coverage": float(np.nanmean([s.coverage for s in scores])),
        "rms_px": float(np.sqrt(mean(rms**2))),
        "bias_px": mean(np.array([s.bias_px for s in scores])),
        "false": float(np.nanmax([s.false for s in scores])),
        "per_section": mean(np.array([s.per_section for s in scores])),
        "images": len(scores),
    }


def accuracy(quick: bool) -> dict[str, dict[str, Any]]:
    """Scores per case and method (and the ridge detector's time per image)."""
    out: dict[str, dict[str, Any]] = {}
    per_case = 1 if quick else 2
    for k, (name, spec) in enumerate(synthetic_cases()):
        imgs = [
            synthetic_stripe(spec, np.random.default_rng(SEED + 100 * k + j))
            for j in range(per_case)
        ]
        truth = spec.truth()
        out[name] = _methods(imgs, [(truth, truth)] * len(imgs), spec.shape)
        print(f"  {name:32s} " + _line(out[name]), flush=True)
    grouped: dict[str, list[Any]] = {}
    for name, img, truth, cover in rendered_cases(quick):
        grouped.setdefault(name, []).append((img, truth, cover))
    for name, items in grouped.items():
        imgs = [i for i, _, _ in items]
        out[name] = _methods(imgs, [(t, c) for _, t, c in items], imgs[0].shape)
        print(f"  {name:32s} " + _line(out[name]), flush=True)
    return out


def _methods(
    imgs: list[np.ndarray], truths: list[tuple[np.ndarray, np.ndarray]], shape: Any
) -> dict[str, Any]:
    res: dict[str, Any] = {}
    for m, fn in METHODS.items():
        scores, times = [], []
        for img, (truth, cover) in zip(imgs, truths):
            t = time.perf_counter()
            found = fn(img)
            times.append(time.perf_counter() - t)
            scores.append(
                score_centres(found, truth, shape=shape, margin_px=MARGIN, cover=cover)
            )
        res[m] = {**_pool(scores), "ms_per_image": 1e3 * statistics.median(times)}
    return res


def _line(r: dict[str, Any]) -> str:
    return "  ".join(
        f"{m} {r[m]['coverage'] * 100:5.1f}% {r[m]['rms_px']:.3f}px" for m in METHODS
    )


@contextmanager
def _one_core() -> Iterator[None]:
    """Run on one CPU: the affinity of this process and OpenCV's thread count."""
    import cv2

    threads = cv2.getNumThreads()
    mask = os.sched_getaffinity(0) if hasattr(os, "sched_getaffinity") else None
    cv2.setNumThreads(1)
    if mask:
        os.sched_setaffinity(0, {min(mask)})
    try:
        yield
    finally:
        cv2.setNumThreads(threads)
        if mask:
            os.sched_setaffinity(0, mask)


class _Files:
    """The images of a scan read on access by ``reader``."""

    def __init__(self, files: list[Path], reader: Callable[[Path], np.ndarray]):
        self.files, self.reader = files, reader

    def __len__(self) -> int:
        return len(self.files)

    def __getitem__(self, i: int) -> np.ndarray:
        return self.reader(self.files[i])


def _cv2_read(path: Path) -> np.ndarray:
    from kinecal.io import read_image

    return read_image(path)


def _fast_read(path: Path) -> np.ndarray:
    img = decode_grey_png(path.read_bytes())
    return _cv2_read(path) if img is None else img


def scan_speed(quick: bool) -> dict[str, Any]:
    """A whole scan of 120 PNG images on one core, in-process and as a process."""
    from kinecal import keep_freed_memory
    from kinecal.io import save_sensor, write_image

    keep_freed_memory()  # as the kinecal command does
    sen = paper_sensor()
    ren = StripeRenderer(sen.camera, sen.planes)
    c = np.array([0.0021, -0.0013, 0.1387])
    R = 0.015001
    rng = np.random.default_rng(SEED + 2)
    out: dict[str, Any] = {"target_s": CAMERA_S}
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        for k in range(120):
            write_image(
                d / f"plane_{k:03d}.png", ren.render(sphere_scene(c, R), k, rng)
            )
        files = sorted(d.glob("plane_*.png"))
        save_sensor(d / "sensor.yaml", sen)
        repeat = 2 if quick else 5
        with _one_core():
            for label, reader, method in (
                ("kinecal_png_ridge", _fast_read, "ridge"),
                ("opencv_png_ridge", _cv2_read, "ridge"),
                ("kinecal_png_rows", _fast_read, "rows"),
            ):
                walls, cpus, cloud = [], [], None
                for _ in range(repeat):
                    w, t = time.perf_counter(), time.process_time()
                    cloud = sen.scan(_Files(files, reader), jobs=1, method=method)
                    cpus.append(time.process_time() - t)
                    walls.append(time.perf_counter() - w)
                assert cloud is not None
                fit = fit_sphere(cloud.points)
                out[label] = {
                    "wall_s": statistics.median(walls),
                    "best_wall_s": min(walls),
                    "cpu_s": statistics.median(cpus),
                    "best_cpu_s": min(cpus),
                    "points": int(cloud.points.shape[0]),
                    "centre_error_um": float(np.linalg.norm(fit.center - c) * 1e6),
                    "radius_error_um": float((fit.radius - R) * 1e6),
                    "fit_rms_um": float(fit.rms * 1e6),
                }
                r = out[label]
                print(
                    f"  scan {label:20s} {r['wall_s']:.3f} s wall, {r['cpu_s']:.3f} s "
                    f"CPU on one core (camera {CAMERA_S:.2f} s); sphere centre "
                    f"{r['centre_error_um']:.2f} um, radius {r['radius_error_um']:+.2f} um",
                    flush=True,
                )
            # decoding alone, for the record
            for label, reader in (
                ("decode_kinecal", _fast_read),
                ("decode_opencv", _cv2_read),
            ):
                t = time.perf_counter()
                for f in files:
                    reader(f)
                out[label + "_s"] = time.perf_counter() - t
        cmd = [sys.executable, "-m", "kinecal", "sensor", "reconstruct", str(d)]
        cmd += ["--sensor", str(d / "sensor.yaml"), "--out", str(d / "cloud.csv")]
        cmd += ["--force", "-q", "--jobs", "1"]
        if shutil.which("taskset"):
            cmd = ["taskset", "-c", str(min(os.sched_getaffinity(0))), *cmd]
        env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
        env.pop("PYTHONDONTWRITEBYTECODE", None)
        subprocess.run(cmd, check=True, capture_output=True, env=env)  # warm-up
        times = []
        for _ in range(repeat):
            t = time.perf_counter()
            subprocess.run(cmd, check=True, capture_output=True, env=env)
            times.append(time.perf_counter() - t)
        out["reconstruct_process_one_cpu_s"] = statistics.median(times)
        print(
            f"  kinecal sensor reconstruct --jobs 1 (one CPU, whole process): "
            f"{out['reconstruct_process_one_cpu_s']:.3f} s",
            flush=True,
        )
    return out


def stripe_benchmarks(quick: bool = False) -> dict[str, Any]:
    """Both parts, as one JSON-ready dictionary."""
    print("stripe accuracy (coverage, RMS along the normal) per method:", flush=True)
    acc = accuracy(quick)
    print("scan speed:", flush=True)
    return {"accuracy": acc, "scan": scan_speed(quick), "seed": SEED}


def tables(res: dict[str, Any]) -> str:
    """The accuracy and speed tables of docs/stripes.md, from a result of
    :func:`stripe_benchmarks` (``python -m benchmarks._stripes --tables FILE``)."""

    def cell(r: dict[str, Any]) -> str:
        if not r["coverage"] > 0:
            return "0 % | - | - | -"
        return (
            f"{100 * r['coverage']:.1f} % | {r['rms_px']:.3f} | {r['bias_px']:+.3f} | "
            f"{100 * r['false']:.1f} %"
        )

    head = "| case | " + " | ".join(
        f"{m}: coverage | RMS px | bias px | false" for m in METHODS
    )
    lines = [head + " |", "|---" * (1 + 4 * len(METHODS)) + "|"]
    for name, r in res["accuracy"].items():
        lines.append(f"| {name} | " + " | ".join(cell(r[m]) for m in METHODS) + " |")
    ms = {
        m: np.median([r[m]["ms_per_image"] for r in res["accuracy"].values()])
        for m in METHODS
    }
    lines.append("")
    lines.append(
        "Median time per image over these cases (the benchmark's machine, all CPUs): "
        + ", ".join(f"{m} {t:.1f} ms" for m, t in ms.items())
        + "."
    )
    sc = res["scan"]
    speed = [
        "| 120 PNG images, 1280 x 1024, one core | wall s (best) | CPU s (best) "
        "| points | sphere centre error um | radius error um |",
        "|---|---|---|---|---|---|",
    ]
    labels = {
        "kinecal_png_ridge": "kinecal's PNG decoder + ridge (as `reconstruct` does)",
        "opencv_png_ridge": "OpenCV's PNG decoder + ridge",
        "kinecal_png_rows": "kinecal's PNG decoder + per-row method",
    }
    for k, label in labels.items():
        r = sc[k]
        speed.append(
            f"| {label} | {r['wall_s']:.2f} ({r['best_wall_s']:.2f}) | "
            f"{r['cpu_s']:.2f} ({r.get('best_cpu_s', r['cpu_s']):.2f}) | {r['points']} | "
            f"{r['centre_error_um']:.2f} | {r['radius_error_um']:+.2f} |"
        )
    speed.append("")
    speed.append(
        f"Target: the camera's {sc['target_s']:.2f} s (120 images at 90 Hz). Decoding (wall) "
        f"alone: kinecal {sc['decode_kinecal_s']:.2f} s, OpenCV "
        f"{sc['decode_opencv_s']:.2f} s. `kinecal sensor reconstruct --jobs 1` as a whole "
        f"process on one CPU (start-up, decoding, extraction, reconstruction, CSV): "
        f"{sc['reconstruct_process_one_cpu_s']:.2f} s."
    )
    return "\n".join(lines) + "\n\nSPEED\n\n" + "\n".join(speed) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks --stripes")
    ap.add_argument("--out", default="benchmarks/results-stripes.json")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--tables", metavar="FILE", help="print the docs' tables of FILE")
    args = ap.parse_args(argv)
    if args.tables:
        print(tables(json.loads(Path(args.tables).read_text())))
        return 0
    res = stripe_benchmarks(args.quick)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(args.out).with_suffix(".tmp")
    tmp.write_text(json.dumps(res, indent=2) + "\n")
    os.replace(tmp, args.out)
    print(f"-> {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
