"""Second fault audit (``kinecal sensor``): stripe-image folders whose file names do not
give one light plane each, or a plane the sensor file lacks. In-process."""

from __future__ import annotations

import shutil

import pytest

from tests.cli_contract import failed_with, run_kinecal


@pytest.fixture(scope="module")
def scan(tmp_path_factory):
    """A scan of every 16th light plane of the built-in sensor."""
    from kinecal.cli import main

    d = tmp_path_factory.mktemp("scan") / "scan"
    assert (
        main(["sensor", "simulate-scan", "--out", str(d), "--every", "16", "-q"]) == 0
    )
    return d


def _copy(scan, tmp_path):
    d = tmp_path / "scan"
    shutil.copytree(scan, d)
    return d


def _reconstruct(capsys, d, sensor):
    out = d.parent / "cloud.csv"
    return run_kinecal(
        capsys, "sensor", "reconstruct", d, "--sensor", sensor, "--out", out, "-q"
    ), out


def test_a_stripe_image_not_named_plane_nnn_is_refused(capsys, tmp_path, scan):
    """plane_48b.png was read as plane 48 (the last digits of the name)."""
    d = _copy(scan, tmp_path)
    (d / "plane_048.png").rename(d / "plane_48b.png")
    res, out = _reconstruct(capsys, d, scan / "sensor.yaml")
    failed_with(res, "plane_48b.png", "plane_NNN.png")
    assert not out.exists()


def test_two_images_of_one_plane_are_refused(capsys, tmp_path, scan):
    """plane_48.png beside plane_048.png: both used as plane 48 (reconstruct), or one
    dropped unsaid (calibrate-planes)."""
    d = _copy(scan, tmp_path)
    shutil.copy(d / "plane_048.png", d / "plane_48.png")
    res, out = _reconstruct(capsys, d, scan / "sensor.yaml")
    failed_with(res, "plane_48.png", "light plane 48 again", "plane_048.png")
    assert not out.exists()


def test_a_plane_the_sensor_lacks_names_the_image_and_the_sensor(
    capsys, tmp_path, scan
):
    """plane_999.png of a 120-plane sensor: 'light-plane index out of range 0..119:
    16..999' named neither the image nor the sensor file."""
    d = _copy(scan, tmp_path)
    (d / "plane_048.png").rename(d / "plane_999.png")
    res, out = _reconstruct(capsys, d, scan / "sensor.yaml")
    failed_with(res, "plane_999.png", "0..119", "sensor.yaml")
    assert not out.exists()


def test_calibrate_planes_refuses_two_images_of_one_plane(capsys, tmp_path, scan):
    pose = tmp_path / "planes" / "pose_00"
    pose.mkdir(parents=True)
    shutil.copy(scan / "plane_048.png", pose / "board.png")
    shutil.copy(scan / "plane_048.png", pose / "plane_048.png")
    shutil.copy(scan / "plane_048.png", pose / "plane_48.png")
    out = tmp_path / "s.yaml"
    res = run_kinecal(
        capsys, "sensor", "calibrate-planes", tmp_path / "planes", "--camera",
        scan / "sensor.yaml", "--out", out, "-q", "--jobs", "1",
    )  # fmt: skip
    failed_with(res, "plane_48.png", "again")
    assert not out.exists()


@pytest.mark.slow  # 1.4-4.3 s: in test-slow, to keep make test within its budget
def test_calibrate_planes_refuses_a_square_size_in_metres(capsys, tmp_path):
    """--square-mm 0.0025 (2.5 mm in metres) wrote light planes 0.065 mm from the
    camera, 1000 times too close, with exit 0."""
    from kinecal.cli import main

    d = tmp_path / "session"
    argv = ["sensor", "simulate-calibration", "--out", str(d), "-q"]
    assert main([*argv, "--views", "1", "--poses", "3", "--every", "16"]) == 0
    out = tmp_path / "s.yaml"
    res = run_kinecal(
        capsys, "sensor", "calibrate-planes", d / "planes", "--camera",
        d / "truth_sensor.yaml", "--out", out, "-q", "--square-mm", "0.0025",
    )  # fmt: skip
    failed_with(res, "--square-mm 0.0025", "mm from the camera", "in mm")
    assert not out.exists()
    res = run_kinecal(
        capsys, "sensor", "calibrate-planes", d / "planes", "--camera",
        d / "truth_sensor.yaml", "--out", out, "-q",
    )  # fmt: skip
    assert res.code == 0, str(res)


def _edit(scan, tmp_path, edit):
    import yaml

    doc = yaml.safe_load((scan / "sensor.yaml").read_text())
    edit(doc)
    f = tmp_path / "sensor.yaml"
    f.write_text(yaml.safe_dump(doc))
    return f


def _plane(i, row):
    return lambda doc: doc["light_planes"]["planes"].__setitem__(i, row)


def _planes_m(doc):
    doc["light_planes"]["planes"] = [
        [*p[:3], p[3] / 1000] for p in doc["light_planes"]["planes"]
    ]


@pytest.mark.parametrize(
    ("edit", "needles"),
    [  # internal errors (exit 1):
        (_plane(5, [0, 0, "a", 1]), ["planes[5]", "four finite numbers"]),
        (_plane(5, [0, 0, 1]), ["planes[5]", "four finite numbers"]),
        # no file, no plane named, numpy warnings:
        (_plane(5, [0, 0, 0, -65]), ["planes[5]", "normal", "zero"]),
        # read with exit 0 and a wrong cloud:
        (lambda d: d["light_planes"].update(unit="m"), ["unit", "'mm'", "'m'"]),
        (_planes_m, ["b_mm", "millimetres"]),
        (lambda d: d.update(format=2), ["format", "expected 1", "2"]),
        (lambda d: d["camera"].pop("width"), ["missing key", "width"]),
        (lambda d: d["camera"].update(width=1280.5), ["width", "whole number"]),
        (lambda d: d["camera"].update(u0=50000), ["u0", "0..1280", "50000"]),
        (lambda d: d["camera"].update(fx=3.4), ["fx", "in pixels", "3.4"]),
    ],
)
def test_a_damaged_sensor_file_is_refused_naming_the_field(
    capsys, tmp_path, scan, edit, needles
):
    f = _edit(scan, tmp_path, edit)
    res, out = _reconstruct(capsys, scan, f)
    failed_with(res, str(f), *needles)
    assert not out.exists()


def test_simulate_scan_blames_every_when_it_skips_the_lit_planes(capsys, tmp_path):
    """--every 1000 renders plane 0 only, which misses the default sphere: the message
    told to move the sphere (--center-mm) to the working distance, where it is."""
    out = tmp_path / "scan"
    res = run_kinecal(
        capsys, "sensor", "simulate-scan", "--out", out, "--every", "1000", "-q"
    )
    failed_with(res, "--every skips", "1 of 120", "smaller --every")
    assert not out.exists()
