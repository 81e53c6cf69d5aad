"""Issue 35 (5): images checked where they are read: colour refused with a clear
message; sizes against the sensor file's camera and against each other, naming the
image (a 2x2 binned scan with a full-size sensor file ran, and fitted a 15 mm sphere as
18 mm)."""

from __future__ import annotations

import numpy as np
import pytest

from tests.cli_contract import failed_with, run_kinecal

cv2 = pytest.importorskip("cv2")


@pytest.fixture(scope="module")
def scan(tmp_path_factory):
    from kinecal.cli import main

    d = tmp_path_factory.mktemp("faults-scan") / "scan"
    assert main(["sensor", "simulate-scan", "--out", str(d), "--every", "40"]) == 0
    return d


def _copy_scan(scan, dst, change=None):
    import shutil

    shutil.copytree(scan, dst)
    files = sorted(dst.glob("plane_*.png"))
    if change is not None:
        change(files)
    return dst


def test_issue_35_a_scan_reconstructs(scan, capsys, tmp_path):
    res = run_kinecal(
        capsys, "sensor", "reconstruct", scan, "--sensor", scan / "sensor.yaml",
        "--out", tmp_path / "c.csv",
    )  # fmt: skip
    assert res.code == 0, res


def test_issue_35_binned_images_against_a_full_size_sensor(scan, capsys, tmp_path):
    def binned(files):
        for f in files:
            img = cv2.imread(str(f), cv2.IMREAD_UNCHANGED)
            cv2.imwrite(str(f), img[::2, ::2])

    d = _copy_scan(scan, tmp_path / "s", binned)
    res = run_kinecal(
        capsys, "sensor", "reconstruct", d, "--sensor", d / "sensor.yaml",
        "--out", tmp_path / "c.csv",
    )  # fmt: skip
    failed_with(res, "plane_", "640x512 pixels", "expected 1280x1024", "sensor.yaml")
    assert not (tmp_path / "c.csv").exists()


def test_issue_35_one_image_of_another_size(scan, capsys, tmp_path):
    def crop(files):
        f = files[len(files) // 2]
        img = cv2.imread(str(f), cv2.IMREAD_UNCHANGED)
        cv2.imwrite(str(f), img[:1000])

    d = _copy_scan(scan, tmp_path / "s", crop)
    bad = sorted(d.glob("plane_*.png"))[len(list(d.glob("plane_*.png"))) // 2]
    res = run_kinecal(
        capsys, "sensor", "reconstruct", d, "--sensor", d / "sensor.yaml",
        "--out", tmp_path / "c.csv",
    )  # fmt: skip
    failed_with(res, bad.name, "1280x1000 pixels", "expected 1280x1024")


def test_issue_35_a_colour_image_is_refused(scan, capsys, tmp_path):
    f = sorted(scan.glob("plane_*.png"))[len(list(scan.glob("plane_*.png"))) // 2]
    grey = cv2.imread(str(f), cv2.IMREAD_UNCHANGED)[400:600]
    rgb = np.dstack([grey, grey // 2, grey // 3])
    cv2.imwrite(str(tmp_path / "rgb.png"), rgb)
    res = run_kinecal(
        capsys, "sensor", "stripes", tmp_path / "rgb.png", "--out", tmp_path / "s.csv"
    )
    failed_with(res, "rgb.png", "colour image (3 channels)", "grey")


def test_issue_35_a_grey_image_stored_as_rgb_is_converted(scan, capsys, tmp_path):
    f = sorted(scan.glob("plane_*.png"))[len(list(scan.glob("plane_*.png"))) // 2]
    grey = cv2.imread(str(f), cv2.IMREAD_UNCHANGED)[400:600]
    cv2.imwrite(str(tmp_path / "g.png"), np.dstack([grey] * 3))
    cv2.imwrite(str(tmp_path / "f.png"), grey)
    res = run_kinecal(
        capsys, "sensor", "stripes", tmp_path / "g.png", "--out", tmp_path / "a.csv"
    )
    assert res.code == 0, res
    res = run_kinecal(
        capsys, "sensor", "stripes", tmp_path / "f.png", "--out", tmp_path / "b.csv"
    )
    assert res.code == 0, res
    assert (tmp_path / "a.csv").read_text() == (tmp_path / "b.csv").read_text()
