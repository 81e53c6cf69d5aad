"""Fuzz: stripe images (valid ones of odd sizes and depths, damaged files) and point
clouds (degenerate ones too) through the sensor commands' file inputs (issue 21).

Only the generic contract is asserted here: whether a cloud determines a sphere is the
sensor commands' own business (tests/cli/test_fault_*.py pins the degenerate cases).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from tests.cli_contract import check_contract, leftovers, run_kinecal
from tests.fuzz.strategies import FUZZ


@st.composite
def image_bytes(draw: st.DrawFn) -> bytes:
    import cv2

    h = draw(st.integers(1, 48))
    w = draw(st.integers(1, 64))
    depth = draw(st.sampled_from([np.uint8, np.uint16]))
    channels = draw(st.sampled_from([1, 1, 1, 3, 4]))
    kind = draw(st.sampled_from(["stripe", "noise", "flat", "saturated"]))
    top = np.iinfo(depth).max
    if kind == "stripe":
        u0 = draw(st.floats(-5, w + 5))
        sig = draw(st.floats(0.3, 4))
        U = np.arange(w)[None, :].repeat(h, 0)
        img = 0.6 * top * np.exp(-0.5 * ((U - u0) / sig) ** 2)
    elif kind == "noise":
        seed = draw(st.integers(0, 2**16))
        img = np.random.default_rng(seed).uniform(0, top, (h, w))
    elif kind == "flat":
        img = np.full((h, w), draw(st.integers(0, top)))
    else:
        img = np.full((h, w), top)
    img = img.astype(depth)
    if channels > 1:
        img = np.dstack([img] * channels)
    fmt = draw(st.sampled_from([".png", ".png", ".tiff", ".bmp"]))
    if fmt == ".bmp" and depth is np.uint16:
        fmt = ".png"
    ok, buf = cv2.imencode(fmt, img)
    assert ok
    data = buf.tobytes()
    damage = draw(st.sampled_from(["none", "none", "cut", "flip", "junk"]))
    if damage == "cut":
        data = data[: draw(st.integers(0, len(data)))]
    elif damage == "flip" and data:
        i = draw(st.integers(0, len(data) - 1))
        data = data[:i] + bytes([data[i] ^ 0xFF]) + data[i + 1 :]
    elif damage == "junk":
        data = draw(st.binary(max_size=64))
    return data


def test_issue_21_fuzz_stripe_images(capsys, tmp_path):
    @FUZZ
    @given(data=image_bytes())
    def check(data: bytes) -> None:
        d = Path(tempfile.mkdtemp(dir=tmp_path))
        f = d / "img.png"
        f.write_bytes(data)
        out = d / "centres.csv"
        res = run_kinecal(capsys, "sensor", "stripes", f, "--out", out)
        check_contract(res)
        assert out.exists() == (res.code == 0), str(res)
        assert not leftovers(d)

    check()


@st.composite
def cloud_text(draw: st.DrawFn, shapes: tuple[str, ...], n_min: int) -> str:
    n = draw(st.integers(n_min, 60))
    seed = draw(st.integers(0, 2**16))
    rng = np.random.default_rng(seed)
    shape = draw(st.sampled_from(shapes))
    d = rng.normal(size=(n, 3))
    d /= np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
    c = rng.uniform(-200, 200, 3)
    if shape == "cap":
        d[:, 2] = -np.abs(d[:, 2])
        P = c + 15 * d + rng.normal(size=(n, 3)) * draw(st.sampled_from([0, 1e-3, 1]))
    elif shape == "line":
        P = c + np.outer(rng.uniform(-10, 10, n), [1, 2, 3])
    elif shape == "plane":
        P = c + np.column_stack([rng.uniform(-10, 10, (n, 2)), np.zeros(n)])
    elif shape == "circle":
        t = rng.uniform(0, 2 * np.pi, n)
        P = c + 15 * np.column_stack([np.cos(t), np.sin(t), np.zeros(n)])
    elif shape == "point":
        P = np.tile(c, (n, 1))
    else:
        P = rng.uniform(-1e3, 1e3, (n, 3))
    lines = ["x_mm,y_mm,z_mm"] + [",".join(f"{v:.6f}" for v in p) for p in P]
    if draw(st.integers(0, 5)) == 0 and n:
        lines[draw(st.integers(1, n))] = draw(st.sampled_from(["nan,1,2", "1,2", ""]))
    return "\n".join(lines) + "\n"


def _fit_clouds(capsys, tmp_path, clouds) -> None:
    @FUZZ
    @given(cloud=clouds)
    def check(cloud: str) -> None:
        d = Path(tempfile.mkdtemp(dir=tmp_path))
        f = d / "cloud.csv"
        f.write_text(cloud)
        check_contract(run_kinecal(capsys, "sensor", "fit-sphere", f, "--json"))

    check()


def test_issue_21_fuzz_point_clouds(capsys, tmp_path):
    _fit_clouds(capsys, tmp_path, cloud_text(("cap", "noise"), 10))


def test_issue_21_fuzz_degenerate_point_clouds(capsys, tmp_path):
    shapes = ("cap", "line", "plane", "circle", "point", "noise")
    _fit_clouds(capsys, tmp_path, cloud_text(shapes, 0))
