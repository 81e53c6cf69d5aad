"""``kinecal sensor ...`` as a user runs it (DESIGN §11 contract)."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
import yaml


@pytest.fixture
def run_cli(run_cli_here):
    """The commands in this process: these tests check what they compute and say."""
    return run_cli_here


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
    assert set(out) >= {"center_mm", "radius_mm", "rms_mm", "n"}  # DESIGN §11
    assert np.allclose(out["center_mm"], c, atol=1e-3)
    assert abs(out["radius_mm"] - 15.001) < 1e-3
    assert 0.002 < out["rms_mm"] < 0.004 and out["n"] > 2900
    # issue 24: the centre's std and the cap's half-angle (a hemisphere here)
    assert len(out["center_std_mm"]) == 3 and max(out["center_std_mm"]) < 1e-3
    assert 85 < out["cap_half_angle_deg"] < 91 and out["n_points"] == 3000


def test_fit_sphere_bad_file_names_line_and_column(tmp_path, run_cli):
    f = tmp_path / "bad.csv"
    f.write_text("x_mm,y_mm,z_mm\n1,2,3\n1,two,3\n")
    r = run_cli("sensor", "fit-sphere", str(f), "--json")
    assert r.returncode == 2
    assert "bad.csv" in r.stderr and "line 3" in r.stderr and "y_mm" in r.stderr
    f.write_text("x,y,z\n1,2,3\n")
    r = run_cli("sensor", "fit-sphere", str(f))
    assert r.returncode == 2 and "x_mm" in r.stderr


def _cloud_file(path, P_mm):
    np.savetxt(
        path, P_mm, delimiter=",", header="x_mm,y_mm,z_mm", comments="", fmt="%.6f"
    )
    return path


def test_issue_21_fit_sphere_refuses_degenerate_clouds(tmp_path, run_cli):
    """Collinear points (radius 3.5e7 mm, exit 0 before), one circle (4e15 mm) and a
    plane (a traceback): one line naming the file and the reason, exit 2."""
    t = np.linspace(0, 2 * np.pi, 300, endpoint=False)
    rng = np.random.default_rng(1)
    clouds = {
        "line.csv": np.outer(np.linspace(0, 10, 300), [1.0, 2.0, 3.0]),
        "circle.csv": np.column_stack(
            [12 * np.cos(t), 12 * np.sin(t), 0.5 * np.cos(t) + 130]
        ),
        "plane.csv": np.column_stack(
            [rng.uniform(-10, 10, (400, 2)), 0.1 * rng.uniform(-10, 10, 400) + 120]
        ),
    }
    for name, P in clouds.items():
        r = run_cli(
            "sensor", "fit-sphere", str(_cloud_file(tmp_path / name, P)), "--json"
        )
        assert r.returncode == 2, (name, r.stdout)
        lines = r.stderr.strip().splitlines()
        assert len(lines) == 1 and name in lines[0], r.stderr
        assert ("line" if name == "line.csv" else "plane") in lines[0]
        assert "sphere is not determined" in lines[0] and "expected" in lines[0]
        assert "Traceback" not in r.stderr and r.stdout == ""
    r = run_cli("sensor", "fit-sphere", str(tmp_path / "line.csv"), "--radius-mm", "-3")
    assert r.returncode == 2 and "--radius-mm" in r.stderr


def test_issue_24_fit_sphere_segments_the_support_plate(tmp_path, run_cli):
    """A cap of 30 deg with 10 % of its points from the plate around it: the centre
    within a few um (1-6.6 mm before), the plate left out."""
    rng = np.random.default_rng(2)
    n = 9000
    ct = rng.uniform(np.cos(np.radians(30)), 1.0, n)
    phi = rng.uniform(0, 2 * np.pi, n)
    d = np.column_stack(
        [np.sqrt(1 - ct**2) * np.cos(phi), np.sqrt(1 - ct**2) * np.sin(phi), -ct]
    )
    c = np.array([2.0, -1.0, 140.0])
    cap = c + d * (15.0 + rng.normal(0, 0.01, n))[:, None]
    rr, ph = rng.uniform(14.5, 35, 1000), rng.uniform(0, 2 * np.pi, 1000)
    plate = np.column_stack(
        [c[0] + rr * np.cos(ph), c[1] + rr * np.sin(ph), np.full(1000, 128.0)]
    )
    f = _cloud_file(tmp_path / "ball.csv", np.vstack([cap, plate]))
    out = json.loads(run_cli("sensor", "fit-sphere", str(f), "--json").stdout)
    assert np.linalg.norm(np.array(out["center_mm"]) - c) < 0.006
    assert out["n"] <= n and out["n_points"] == n + 1000
    assert out["cap_half_angle_deg"] == pytest.approx(30, abs=1)


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


@pytest.mark.slow  # (a whole image pipeline: make test-slow; `make test` under 90 s)
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


@pytest.mark.slow  # (a whole image pipeline: make test-slow; `make test` under 90 s)
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
    cam_stdout = r.stdout
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
    # issue 24: k3 held (not determined by the chessboard views), and said so
    assert "k3" in cam["calibration"]["fixed"] and "not determined" in cam_stdout
    assert cam["calibration"]["std"]["fx"] > 0.1  # px: from the residuals, not 1e-3
    # camera, target poses and planes in one adjustment, from the same images
    r = run_cli(
        "sensor",
        "calibrate-planes",
        str(cal / "planes"),
        "--chessboard",
        str(cal / "chessboard"),
        "--n-planes",
        "120",
        "--out",
        str(tmp_path / "joint.yaml"),
        "-q",
    )
    assert r.returncode == 0, r.stderr
    assert "re-projection RMS" in r.stdout and "light planes" in r.stdout
    joint = yaml.safe_load((tmp_path / "joint.yaml").read_text())
    info = joint["calibration"]
    assert info["plane_fit_rms_mm"]["mean"] < 0.01 and info["sigma_stripe_px"] < 0.2
    assert abs(joint["camera"]["fx"] / 3423.018 - 1) < 1e-3
    assert info["camera"]["std"]["fx"] > 0.1
    r = run_cli(
        "sensor",
        "calibrate-planes",
        str(cal / "planes"),
        "--out",
        str(tmp_path / "x.yaml"),
    )
    assert r.returncode == 2 and "--chessboard" in r.stderr
    truth = json.loads((cal / "truth.json").read_text())
    assert np.array(truth["planes_T_cam_board_mm"]).shape == (3, 4, 4)
