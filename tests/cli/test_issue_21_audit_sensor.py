"""Issue 21 audit (``kinecal sensor``): an internal error from OpenCV (--board 0x0),
options accepting nan, a scan rendered empty with exit 0, a cloud in metres fitted to a
0.015 mm sphere, messages that named a function instead of the file. In-process."""

from __future__ import annotations

import numpy as np
import pytest

from tests.cli_contract import failed_with, run_kinecal

_bad = failed_with


@pytest.mark.parametrize(
    ("args", "needles"),
    [
        (["--board", "0x0"], ["--board", "at least 3"]),
        (["--board", "10x10"], ["--board", "one even and one odd"]),
        (["--board", "7x9"], ["--board", "one even and one odd"]),
        (["--square-mm", "nan"], ["--square-mm", "finite", "nan"]),
    ],
)
@pytest.mark.parametrize("command", ["calibrate-camera", "calibrate-planes"])
def test_issue_21_audit_board_options(capsys, tmp_path, command, args, needles):
    extra = ["--chessboard", str(tmp_path)] if command == "calibrate-planes" else []
    out = tmp_path / "out.yaml"
    res = run_kinecal(
        capsys, "sensor", command, tmp_path, "--out", out, "-q", *extra, *args
    )
    _bad(res, *needles)
    assert not out.exists()


def test_issue_21_audit_camera_found_in_too_few_images_names_the_folder(
    capsys, tmp_path
):
    from kinecal.io import write_image

    write_image(tmp_path / "view_00.png", np.full((40, 50), 90, np.uint8))
    res = run_kinecal(
        capsys, "sensor", "calibrate-camera", tmp_path, "--out", tmp_path / "c.yaml",
        "-q", "--jobs", "1",
    )  # fmt: skip
    last = _bad(res, str(tmp_path), "found in 0 of 1 images", "--board 10x7")
    assert "calibrate_camera" not in last


def test_planes_chessboard_found_in_too_few_views_names_the_folder(capsys, tmp_path):
    """calibrate-planes: the folder of the views the board was not found in (the
    --chessboard folder, or the target poses' folder), and the board looked for."""
    from kinecal.io import write_image

    blank = np.full((40, 50), 90, np.uint8)
    views, poses = tmp_path / "views", tmp_path / "poses"
    write_image(views / "view_00.png", blank)
    for k in range(3):
        write_image(poses / f"pose_{k}" / "board.png", blank)
        write_image(poses / f"pose_{k}" / "plane_000.png", blank)
    out = tmp_path / "s.yaml"
    res = run_kinecal(
        capsys, "sensor", "calibrate-planes", poses, "--chessboard", views,
        "--out", out, "-q", "--jobs", "1",
    )  # fmt: skip
    _bad(res, str(views), "found in 0 of 1 camera views", "--board 10x7")
    cam = tmp_path / "cam.yaml"
    cam.write_text(
        "camera: {width: 50, height: 40, fx: 100.0, fy: 100.0, u0: 25.0, v0: 20.0,"
        " k1: 0.0, k2: 0.0, k3: 0.0, p1: 0.0, p2: 0.0}\n"
    )
    res = run_kinecal(
        capsys, "sensor", "calibrate-planes", poses, "--camera", cam,
        "--out", out, "-q", "--jobs", "1",
    )  # fmt: skip
    _bad(res, str(poses), "found at 0 of 3 target poses", "--board 10x7")
    assert not out.exists()


def test_issue_21_audit_stripes_tiny_image_and_sigma(capsys, tmp_path):
    from kinecal.io import write_image

    f = write_image(tmp_path / "tiny.png", np.full((1, 1), 200, np.uint8))
    out = tmp_path / "c.csv"
    res = run_kinecal(capsys, "sensor", "stripes", f, "--out", out)
    _bad(res, "tiny.png", "1x1 pixels", "at least 3x3")
    g = write_image(tmp_path / "g.png", np.zeros((20, 20), np.uint8))
    for sigma, needle in (("nan", "nan"), ("0", "0.5..10 px"), ("50", "0.5..10 px")):
        res = run_kinecal(
            capsys, "sensor", "stripes", g, "--out", out, "--sigma-px", sigma
        )
        _bad(res, "--sigma-px", needle)
    assert not out.exists()


def _cloud(tmp_path, scale: float):
    rng = np.random.default_rng(3)
    u = rng.normal(size=(300, 3))
    u[:, 2] = -np.abs(u[:, 2])  # the cap facing the camera
    p = np.array([1.0, -2.0, 125.0]) + 15.0 * u / np.linalg.norm(u, axis=1)[:, None]
    f = tmp_path / "cloud.csv"
    f.write_text(
        "x_mm,y_mm,z_mm\n"
        + "\n".join(",".join(f"{v:.9f}" for v in r) for r in p * scale)
    )
    return f


def test_issue_21_audit_fit_sphere_options_and_metres(capsys, tmp_path):
    f = _cloud(tmp_path, 1.0)
    res = run_kinecal(capsys, "sensor", "fit-sphere", f, "--json")
    assert res.code == 0, str(res)
    for k, needle in (("-1", ">= 0"), ("nan", "finite")):
        res = run_kinecal(capsys, "sensor", "fit-sphere", f, "--outlier-k", k)
        _bad(res, "--outlier-k", needle)
    res = run_kinecal(capsys, "sensor", "fit-sphere", _cloud(tmp_path, 1e-3), "--json")
    _bad(res, "cloud.csv", "looks like metres")


@pytest.mark.parametrize(
    ("args", "needles"),
    [
        (["--center-mm", "0,0,nan"], ["--center-mm", "finite"]),
        (["--center-mm", "0,0,-140"], ["--center-mm", "in front of the camera"]),
        (["--radius-mm", "500"], ["--center-mm", "in front of the camera"]),
        (["--center-mm", "200,0,140"], ["--center-mm", "outside the camera's"]),
        (["--center-mm", "0,0,5000"], ["--center-mm", "no rendered light plane"]),
    ],
)
def test_issue_21_audit_simulate_scan_that_sees_nothing(
    capsys, tmp_path, args, needles
):
    out = tmp_path / "scan"
    res = run_kinecal(capsys, "sensor", "simulate-scan", "--out", out, "-q", *args)
    _bad(res, *needles)
    assert not out.exists()


def test_issue_21_audit_sensor_file_with_nan_names_the_file(capsys, tmp_path):
    from kinecal.io import save_sensor
    from kinecal.sensor import paper_sensor

    f = tmp_path / "sensor.yaml"
    save_sensor(f, paper_sensor(), {})
    f.write_text(f.read_text().replace("fx: 3423.018", "fx: .nan"))
    res = run_kinecal(
        capsys, "sensor", "reconstruct", tmp_path, "--sensor", f, "--out",
        tmp_path / "cl.csv", "-q",
    )  # fmt: skip
    _bad(res, "sensor.yaml", "camera parameter fx", "finite")
