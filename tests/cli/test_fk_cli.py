"""`kinecal fk`, `kinecal robots`, `--version`, `--help`: the contract of DESIGN §11."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

DATA = Path(__file__).parents[1] / "data" / "fanuc_lrmate200id"
VECTORS = json.loads((DATA / "test_vectors.json").read_text())


@pytest.fixture
def run_cli(run_cli_here):
    """The commands in this process: these tests check what they compute and say."""
    return run_cli_here


@pytest.mark.parametrize("key", sorted(VECTORS))
def test_fk_json_reproduces_reference_vectors(run_cli, key):
    v = VECTORS[key]
    robot = (
        "fanuc-lrmate200id-7l"
        if key.startswith("lrmate200id7l")
        else "fanuc-lrmate200id"
    )
    res = run_cli("fk", "--robot", robot, "--json", "--", *map(str, v["J_ctrl_deg"]))
    assert res.returncode == 0, res.stderr
    out = json.loads(res.stdout)
    assert set(out) == {"flange_mm", "wpr_deg"}
    np.testing.assert_allclose(out["flange_mm"], v["flange_world_mm"], atol=5e-5)
    if abs(v["wpr_deg"][1]) < 89:  # away from the WPR gimbal lock, angles are unique
        np.testing.assert_allclose(out["wpr_deg"], v["wpr_deg"], atol=5e-5)


def test_fk_with_robot_file(run_cli, tmp_path):
    f = tmp_path / "bot.yaml"
    f.write_text(
        "name: bot\nconvention: mdh\nunits: {length: m, angle: rad}\njoints:\n"
        "  - {theta_offset: 0, d: 0.3, a: 0, alpha: 0}\n"
        "  - {theta_offset: 0, d: 0, a: 0.5, alpha: 0}\n"
    )
    res = run_cli("fk", "--robot", str(f), "--json", "0", "0")
    assert res.returncode == 0, res.stderr
    assert json.loads(res.stdout)["flange_mm"] == pytest.approx([500.0, 0.0, 300.0])


@pytest.mark.parametrize(
    ("args", "match"),
    [
        (["fk", "--robot", "fanuc-lrmate200id", "1", "2"], "has 6 joints; got 2"),
        (["fk", "--robot", "no-such-robot", "1", "2"], "unknown robot 'no-such-robot'"),
        (
            ["fk", "--robot", "missing.yaml", "1", "2"],
            "missing.yaml: robot file not found",
        ),
        (["fk", "--robot", "fanuc-lrmate200id"], "Missing argument"),
    ],
)
def test_fk_bad_input_exits_2_with_one_line(run_cli, args, match):
    res = run_cli(*args)
    assert res.returncode == 2
    assert match in res.stderr


def test_bad_robot_file_names_the_key(run_cli, tmp_path):
    f = tmp_path / "bad.yaml"
    f.write_text(
        "name: bot\nconvention: dh\nunits: {length: mm, angle: degs}\njoints:\n"
        "  - {theta_offset: 0, d: 0, a: 0, alpha: 0}\n"
        "  - {theta_offset: 0, d: 0, a: 500, alpha: 0}\n"
    )
    res = run_cli("fk", "--robot", str(f), "0", "0")
    assert res.returncode == 2
    line = res.stderr.strip()
    assert "\n" not in line and "units.angle" in line and "'degs'" in line
    f.write_text(
        "name: bot\nconvention: dh\nunits: {length: mm, angle: deg}\njoints:\n"
        "  - {theta_offset: 0, d: 0, alpha: 0}\n  - {theta_offset: 0, d: 0, a: 500, alpha: 0}\n"
    )
    res = run_cli("fk", "--robot", str(f), "0", "0")
    assert res.returncode == 2 and "joints[0]: missing key 'a'" in res.stderr


def test_version_help_and_robots(run_cli):
    from kinecal import __version__

    assert __version__ in run_cli("--version").stdout
    res = run_cli("--help")
    assert res.returncode == 0 and "fk" in res.stdout
    res = run_cli("fk", "--help")
    assert "NAME|FILE" in res.stdout and "--json" in res.stdout
    res = run_cli("robots")
    for name in ("fanuc-lrmate200id", "fanuc-lrmate200id-7l", "ur10", "franka-fr3"):
        assert name in res.stdout
