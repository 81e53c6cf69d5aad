"""Issue 36 point 6: the fast paths of ``kinecal sensor reconstruct`` give what the
slow ones gave (the cloud's CSV text, the decoded images)."""

from __future__ import annotations

import io

import cv2
import numpy as np
import pytest

from kinecal.io import _sensor_files
from kinecal.sensor import decode_grey_png


@pytest.mark.parametrize("block", [7, 20_000])
def test_csv_blocks_are_savetxts_text(monkeypatch, block):
    monkeypatch.setattr(_sensor_files, "_BLOCK", block)
    rng = np.random.default_rng(5)
    data = np.column_stack(
        [
            rng.normal(0, 300, (50, 3)),
            rng.uniform(0, 1280, (50, 2)),
            rng.integers(0, 120, 50).astype(float),
        ]
    )
    data[3, 1] = np.nan
    data[4, 0] = -0.0
    fmt = ["%.6f"] * 3 + ["%.4f"] * 2 + ["%d"]
    cols = ["x_mm", "y_mm", "z_mm", "u_px", "v_px", "plane"]
    ref = io.StringIO()
    ref.write(",".join(cols) + "\n")
    np.savetxt(ref, data, fmt=fmt, delimiter=",")
    text = b"".join(_sensor_files._csv_blocks(cols, data, fmt)).decode()
    assert text == ref.getvalue()
    empty = b"".join(_sensor_files._csv_blocks(cols, np.zeros((0, 6)), fmt)).decode()
    assert empty == ",".join(cols) + "\n"


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_scan_images_decode_as_opencv_decodes_them(dtype):
    """A stripe image of the size of the sensor's (1280 x 1024), written by OpenCV as
    the simulator writes it: the one-row integral gives OpenCV's pixels."""
    rng = np.random.default_rng(6)
    top = np.iinfo(dtype).max
    img = np.clip(rng.normal(8, 2, (1024, 1280)), 0, top)
    img[:, 600:606] = top  # a saturated stripe: large sums along the rows
    img = img.astype(dtype)
    _, buf = cv2.imencode(".png", img)
    out = decode_grey_png(buf.tobytes())
    assert out is not None
    np.testing.assert_array_equal(out, img)


@pytest.mark.parametrize("isal", [True, False])
def test_inflation_with_and_without_isal(monkeypatch, isal):
    """The optional ISA-L inflation (package ``isal``) and the standard library's give
    the same image; broken data go to OpenCV (None) with either."""
    import sys

    from kinecal.sensor import _png

    if isal:
        pytest.importorskip("isal")
    else:
        monkeypatch.setitem(sys.modules, "isal", None)  # import isal fails
    monkeypatch.setattr(_png, "_INFLATE", [])
    rng = np.random.default_rng(7)
    img = np.clip(rng.normal(8, 2, (120, 160)), 0, 255).astype(np.uint8)
    data = cv2.imencode(".png", img)[1].tobytes()
    np.testing.assert_array_equal(decode_grey_png(data), img)
    assert _png._INFLATE[0][0].__module__.startswith("isal") == isal
    _, idat = _png._chunks(data)
    assert _png._inflate(idat[:-4] + bytes(4)) is None  # its Adler-32 wrong
    assert _png._inflate(idat[:20]) is None  # cut short


def test_reconstruct_gives_the_cloud_of_the_slow_path(tmp_path, capsys):
    """``kinecal sensor reconstruct`` (kinecal's decoder, block-formatted CSV) writes the
    text the slow path gives: images read by OpenCV, the scan, numpy.savetxt."""
    from kinecal.io import read_image, save_sensor, write_image
    from kinecal.sensor import StripeRenderer, paper_sensor, sphere_scene
    from tests.cli_contract import run_kinecal

    sen = paper_sensor()
    ren = StripeRenderer(sen.camera, sen.planes)
    scene = sphere_scene(np.array([0.0021, -0.0013, 0.1387]), 0.015)
    rng = np.random.default_rng(8)
    planes = (30, 60, 90)
    for k in planes:
        write_image(tmp_path / f"plane_{k:03d}.png", ren.render(scene, k, rng))
    save_sensor(tmp_path / "sensor.yaml", sen)
    res = run_kinecal(
        capsys, "sensor", "reconstruct", tmp_path, "--sensor",
        tmp_path / "sensor.yaml", "--out", tmp_path / "cloud.csv", "-q", "--jobs", "1",
    )  # fmt: skip
    assert res.code == 0, res
    imgs = [read_image(tmp_path / f"plane_{k:03d}.png") for k in planes]
    cloud = sen.scan(imgs, np.array(planes), jobs=1)
    assert cloud.points.shape[0] > 300
    ref = io.StringIO()
    ref.write("x_mm,y_mm,z_mm,u_px,v_px,plane\n")
    data = np.column_stack([cloud.points * 1e3, cloud.uv, cloud.plane.astype(float)])
    np.savetxt(ref, data, fmt=["%.6f"] * 3 + ["%.4f"] * 2 + ["%d"], delimiter=",")
    assert (tmp_path / "cloud.csv").read_text() == ref.getvalue()


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("n", [1, 2, 7, 2322, 5120])
def test_ridge_median_has_numpys_bits(dtype, n):
    from kinecal.sensor._ridge import _median

    rng = np.random.default_rng(n)
    a = np.abs(rng.normal(0, 3, n)).astype(dtype)
    a[: n // 3] = np.round(a[: n // 3])  # ties, as in the images' grey levels
    assert _median(a) == float(np.median(a))
    assert _median(a.reshape(1, -1)[:, ::1]) == float(np.median(a))
