"""``kinecal sensor ...`` as a user runs it (DESIGN §11 contract)."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
import yaml


def test_fit_sphere_json_contract(tmp_path, run_cli):
    rng = np.random.default_rng(0)
    d = rng.normal(size=(3000, 3))
    d[:, 2] = -np.abs(d[:, 2])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    c = np.array([12.5, -3.0, 140.0])
    P = c + d * (15.001 + rng.normal(size=(3000, 1)) * 0.003)
    f = tmp_path / "cloud.csv"
    np.savetxt(f, P, delimiter=",", header="x_mm,y_mm,z_mm", comments="", fmt="%.6f")
    r = run_cli("sensor", "fit-sphere", str(f), "--json")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert set(out) == {"center_mm", "radius_mm", "rms_mm", "n"}
    assert np.allclose(out["center_mm"], c, atol=1e-3)
    assert abs(out["radius_mm"] - 15.001) < 1e-3
    assert 0.002 < out["rms_mm"] < 0.004 and out["n"] > 2900


def test_fit_sphere_bad_file_names_line_and_column(tmp_path, run_cli):
    f = tmp_path / "bad.csv"
    f.write_text("x_mm,y_mm,z_mm\n1,2,3\n1,two,3\n")
    r = run_cli("sensor", "fit-sphere", str(f), "--json")
    assert r.returncode == 2
    assert "bad.csv" in r.stderr and "line 3" in r.stderr and "y_mm" in r.stderr
    f.write_text("x,y,z\n1,2,3\n")
    r = run_cli("sensor", "fit-sphere", str(f))
    assert r.returncode == 2 and "x_mm" in r.stderr


def test_stripes_contract_and_no_overwrite(tmp_path, run_cli):
    H, W = 1024, 1280
    u0 = 500.3 + 0.02 * np.arange(H)
    U = np.arange(W)[None, :]
    img = 8 + 160 * np.exp(-0.5 * ((U - u0[:, None]) / 1.5) ** 2)
    png = tmp_path / "stripe.png"
    cv2.imwrite(str(png), np.clip(np.rint(img), 0, 255).astype(np.uint8))
    out = tmp_path / "centres.csv"
    r = run_cli("sensor", "stripes", str(png), "--out", str(out))
    assert r.returncode == 0, r.stderr
    data = np.genfromtxt(out, delimiter=",", names=True)
    assert data.dtype.names[:2] == ("u_px", "v_px") and data.size == H
    assert np.max(np.abs(data["u_px"] - u0[data["v_px"].astype(int)])) < 0.05
    r = run_cli("sensor", "stripes", str(png), "--out", str(out))
    assert r.returncode == 2 and "--force" in r.stderr
    r = run_cli(
        "sensor", "stripes", str(tmp_path / "missing.png"), "--out", str(out), "--force"
    )
    assert r.returncode == 2 and "missing.png" in r.stderr


def test_issue_24_stripes_of_any_direction_with_every_column(tmp_path, run_cli):
    """A horizontal, curved stripe: one centre per column, with the normal, width,
    amplitude and flags; --method rows (the first extractor) finds little of it."""
    from kinecal.sensor import StripeSpec, score_centres, synthetic_stripe

    spec = StripeSpec(angle_deg=90.0, radius_px=1500.0, speckle_k=8.0, bit_depth=16)
    png = tmp_path / "curved.png"
    cv2.imwrite(str(png), synthetic_stripe(spec, np.random.default_rng(5)))
    out = tmp_path / "centres.csv"
    r = run_cli("sensor", "stripes", str(png), "--out", str(out))
    assert r.returncode == 0, r.stderr
    header = out.read_text().splitlines()[0].split(",")
    assert header == ["u_px", "v_px", "nx", "ny", "width_px", "peak", "flags"]
    data = np.loadtxt(out, delimiter=",", skiprows=1)
    s = score_centres(data, spec.truth(), shape=spec.shape, margin_px=8)
    assert s.coverage >= 0.98 and s.rms_px <= 0.15 and s.false <= 0.01
    assert np.all(data[:, 6] == np.rint(data[:, 6]))  # flags are integers
    assert np.median(np.abs(data[:, 3])) > 0.9  # normals along v: a flat stripe
    assert np.median(data[:, 5]) == pytest.approx(150.0 * 257, rel=0.1)  # 16 bit
    rows = tmp_path / "rows.csv"
    r = run_cli("sensor", "stripes", str(png), "--out", str(rows), "--method", "rows")
    assert r.returncode == 0, r.stderr
    found = np.loadtxt(rows, delimiter=",", skiprows=1, ndmin=2)
    assert score_centres(found, spec.truth(), shape=spec.shape).coverage < 0.5
    r = run_cli(
        "sensor", "stripes", str(png), "--out", str(rows), "--method", "rows",
        "--sigma-px", "2", "--force",
    )  # fmt: skip
    assert r.returncode == 2 and "--sigma-px" in r.stderr
    r = run_cli("sensor", "stripes", str(png), "--out", str(rows), "--sigma-px", "40")
    assert r.returncode == 2 and "sigma_px" in r.stderr


def test_simulate_reconstruct_fit_chain(tmp_path, run_cli):
    scan = tmp_path / "scan"
    r = run_cli(
        "sensor",
        "simulate-scan",
        "--out",
        str(scan),
        "--every",
        "3",
        "--center-mm",
        "2,-1,138",
        "-q",
    )
    assert r.returncode == 0, r.stderr
    assert len(list(scan.glob("plane_*.png"))) == 40
    truth = json.loads((scan / "truth.json").read_text())
    cloud = tmp_path / "cloud.csv"
    r = run_cli(
        "sensor",
        "reconstruct",
        str(scan),
        "--sensor",
        str(scan / "sensor.yaml"),
        "--out",
        str(cloud),
        "-q",
    )
    assert r.returncode == 0, r.stderr
    serial = tmp_path / "cloud-serial.csv"
    args = ("reconstruct", str(scan), "--sensor", str(scan / "sensor.yaml"), "-q")
    r = run_cli("sensor", *args, "--out", str(serial), "--jobs", "1")
    assert r.returncode == 0, r.stderr
    assert serial.read_bytes() == cloud.read_bytes()  # any number of threads
    r = run_cli("sensor", *args, "--out", str(serial), "--jobs", "-1", "--force")
    assert r.returncode == 2 and "--jobs" in r.stderr
    r = run_cli("sensor", "fit-sphere", str(cloud), "--json")
    out = json.loads(r.stdout)
    assert np.allclose(out["center_mm"], truth["center_mm"], atol=0.005)
    assert abs(out["radius_mm"] - truth["radius_mm"]) < 0.005
    # the first extractor, for comparisons
    rows = tmp_path / "cloud-rows.csv"
    r = run_cli("sensor", *args, "--out", str(rows), "--method", "rows")
    assert r.returncode == 0, r.stderr
    r = run_cli("sensor", "fit-sphere", str(rows), "--json")
    assert abs(json.loads(r.stdout)["radius_mm"] - truth["radius_mm"]) < 0.005
    # a camera-only file is refused by reconstruct, with the reason
    doc = yaml.safe_load((scan / "sensor.yaml").read_text())
    del doc["light_planes"]
    (tmp_path / "cam.yaml").write_text(yaml.safe_dump(doc))
    r = run_cli(
        "sensor",
        "reconstruct",
        str(scan),
        "--sensor",
        str(tmp_path / "cam.yaml"),
        "--out",
        str(tmp_path / "c2.csv"),
    )
    assert r.returncode == 2 and "light_planes" in r.stderr


def test_calibration_commands(tmp_path, run_cli):
    cal = tmp_path / "cal"
    r = run_cli(
        "sensor",
        "simulate-calibration",
        "--out",
        str(cal),
        "--views",
        "10",
        "--poses",
        "3",
        "--every",
        "10",
        "-q",
    )
    assert r.returncode == 0, r.stderr
    r = run_cli(
        "sensor",
        "calibrate-camera",
        str(cal / "chessboard"),
        "--out",
        str(tmp_path / "camera.yaml"),
        "--jobs",
        "2",
        "-q",
    )
    assert r.returncode == 0, r.stderr
    assert "re-projection RMS" in r.stdout
    cam = yaml.safe_load((tmp_path / "camera.yaml").read_text())
    assert abs(cam["camera"]["fx"] / 3423.018 - 1) < 2e-3
    assert cam["calibration"]["rms_reprojection_px"] < 0.2
    r = run_cli(
        "sensor",
        "calibrate-planes",
        str(cal / "planes"),
        "--camera",
        str(tmp_path / "camera.yaml"),
        "--n-planes",
        "120",
        "--out",
        str(tmp_path / "sensor.yaml"),
        "--jobs",
        "2",
        "-q",
    )
    assert r.returncode == 0, r.stderr
    sen = yaml.safe_load((tmp_path / "sensor.yaml").read_text())
    assert len(sen["light_planes"]["planes"]) == 120
    assert sen["calibration"]["plane_fit_rms_mm"]["mean"] < 0.02
