"""Issue 26: start-up. Packages load their modules when a name is first used, and the
``kinecal`` command imports a command's module only when that command runs."""

from __future__ import annotations

import importlib
import inspect
import json
import subprocess
import sys

import click
import pytest

LAZY = (
    "kinecal",
    "kinecal.identification",
    "kinecal.io",
    "kinecal.iso9283",
    "kinecal.measurement",
    "kinecal.models",
    "kinecal.report",
    "kinecal.robot",
    "kinecal.sensor",
)


def _modules_after(code: str) -> set[str]:
    """The modules a fresh interpreter has imported after running ``code``."""
    out = subprocess.run(
        [
            sys.executable,
            "-c",
            f"{code}\nimport sys, json; print(json.dumps(list(sys.modules)))",
        ],
        capture_output=True,
        text=True,
        check=True,
    )
    return set(json.loads(out.stdout.splitlines()[-1]))


@pytest.mark.parametrize("package", LAZY)
def test_issue_26_every_public_name_of_a_lazy_package_is_its_modules_object(package):
    pkg = importlib.import_module(package)
    assert sorted(pkg.__all__) == sorted(set(pkg.__all__))
    for name in pkg.__all__:
        value = getattr(pkg, name)
        if callable(value):
            home = importlib.import_module(value.__module__)
            assert getattr(home, name, value) is value, name
        assert name in dir(pkg)
    with pytest.raises(AttributeError, match="no attribute 'not_a_name'"):
        pkg.not_a_name  # noqa: B018


def test_issue_26_help_imports_no_command_and_no_numpy():
    loaded = _modules_after(
        "import sys; sys.argv = ['kinecal', '--help']\n"
        "from kinecal.cli import main\n"
        "try:\n    main(['--help'])\nexcept SystemExit:\n    pass"
    )
    assert not {"numpy", "yaml", "scipy"} & loaded
    # the error path (stdlib and click only) serves every command; no command's module
    commands = [m for m in loaded if m.startswith("kinecal.cli._")]
    assert commands in ([], ["kinecal.cli._errors"]), sorted(loaded)


def test_issue_26_a_sphere_fit_imports_neither_scipy_nor_opencv():
    loaded = _modules_after(
        "import numpy as np\nfrom kinecal.sensor import fit_sphere\n"
        "d = np.random.default_rng(0).normal(size=(500, 3))\n"
        "fit_sphere(d / np.linalg.norm(d, axis=1, keepdims=True))"
    )
    assert "kinecal.sensor._sphere" in loaded
    assert not {"scipy", "cv2", "kinecal.sensor._stripes"} & loaded


def test_issue_26_reading_a_robot_does_not_import_the_urdf_reader():
    loaded = _modules_after("from kinecal.robot import load_robot\nload_robot('ur10')")
    assert (
        not {"xml.etree.ElementTree", "kinecal.robot._urdf", "kinecal.identification"}
        & loaded
    )


def test_issue_26_the_command_table_is_the_commands_own_help():
    """`kinecal --help` lists the commands from a table, without importing them: each
    entry must name the command's module and function and the first paragraph of its
    help, so the listing is what click would write from the commands themselves."""
    from kinecal.cli import COMMANDS, cli

    names = set()
    for name, (module, attr, first) in COMMANDS.items():
        cmd = getattr(importlib.import_module(f"kinecal.cli.{module}"), attr)
        assert isinstance(cmd, click.Command) and cmd.name == name
        assert inspect.cleandoc(cmd.help or "").split("\n\n")[0] == first, name
        for limit in (30, 45, 60, 80):
            assert click.Command(name, help=first).get_short_help_str(limit) == (
                cmd.get_short_help_str(limit)
            )
        names.add(name)
    assert names == set(cli.list_commands(click.Context(cli)))


def test_issue_26_a_calibration_does_not_import_numpy_ma_or_the_ik(tmp_path):
    """np.median, np.quantile, np.unique and np.isin import numpy.ma on first use (5-10 ms
    of every command's start); the calibration path uses kinecal._stats instead. Nor does
    it load the inverse kinematics."""
    from pathlib import Path

    data = Path(__file__).parent / "data" / "real" / "ur10_mocap.csv"
    out = tmp_path / "cal"
    loaded = _modules_after(
        "from kinecal.cli import main\n"
        f"args = ['calibrate', {str(data)!r}, '--robot', 'ur10', '--out', {str(out)!r}, "
        "'--no-report', '-q']\n"
        "try:\n    main(args)\nexcept SystemExit as e:\n    assert not e.code, e.code"
    )
    assert (out / "model.yaml").is_file()
    assert "kinecal.identification._calibrate" in loaded
    assert not {"numpy.ma", "kinecal.models._ik_lm"} & loaded


def test_issue_36_calibrate_without_the_report_imports_no_figures(tmp_path):
    """``kinecal calibrate --no-report`` writes model.yaml, report.json and
    residuals.csv: the figures, the HTML and the SVG code are not imported."""
    from kinecal.io import measurements_to_csv
    from kinecal.simulation import LaserTracker, experiment2

    e = experiment2(5, n_train=60, n_side=4, tracker=LaserTracker(5e-6, 0.0))
    csv = tmp_path / "poses.csv"
    csv.write_text(measurements_to_csv(e.train, e.truth.robot))
    argv = ["calibrate", str(csv), "--robot", e.truth.robot.name, "--model"]
    argv += ["kinematic", "--out", str(tmp_path / "o"), "-q", "--no-report"]
    loaded = _modules_after(f"from kinecal.cli import main\nassert main({argv!r}) == 0")
    assert "kinecal.report._poses" in loaded and "kinecal.report._summary" in loaded
    assert (
        not {
            "kinecal.report._calibration",
            "kinecal.report._figures",
            "kinecal.report._html",
            "kinecal.report._svg",
        }
        & loaded
    )


def test_issue_36_a_full_fit_with_sigmas_and_no_cv_imports_no_selection(tmp_path):
    """``--model full --cv off`` on tracker poses with their sigma column (the twin as
    ``kinecal simulate`` writes it): the sigma check's median does not load numpy.ma,
    and neither the model selection nor the cross-validation is imported (they run
    only for ``--model auto`` and ``--cv K``)."""
    from kinecal.io import measurements_to_csv
    from kinecal.simulation import LaserTracker, experiment2

    e = experiment2(5, n_train=60, n_side=4, tracker=LaserTracker(5e-6, 0.0))
    csv = tmp_path / "poses.csv"
    text = measurements_to_csv(e.train, e.truth.robot)
    if "sigma_mm" not in text.splitlines()[0]:  # the column the check reads
        lines = text.splitlines()
        text = "\n".join([lines[0] + ",sigma_mm"] + [ln + ",0.005" for ln in lines[1:]])
    csv.write_text(text + "\n")
    argv = ["calibrate", str(csv), "--robot", e.truth.robot.name, "--model", "full"]
    argv += ["--cv", "off", "--out", str(tmp_path / "o"), "-q", "--no-report"]
    loaded = _modules_after(f"from kinecal.cli import main\nassert main({argv!r}) == 0")
    assert "kinecal.identification._calibrate" in loaded
    assert "numpy.ma" not in loaded
    assert not [m for m in loaded if m.startswith("kinecal.identification.selection")]
