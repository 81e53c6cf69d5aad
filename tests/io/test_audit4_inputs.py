"""Audit 4: inputs that parse but cannot be right, refused with the file, the place and
the value expected (exit 2), never accepted with a silently wrong result.

Each test damages a file kinecal wrote itself (tests/cli_contract.make_point_data) the
way a hand edit, a unit mix-up or a truncated copy does, runs the command as a user
does (in-process) and checks the one ``Error:`` line and that nothing was written.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from kinecal import _yaml as yaml
from tests.cli_contract import failed_with, make_point_data, run_kinecal


@pytest.fixture(scope="module")
def pt(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    return make_point_data(tmp_path_factory.mktemp("audit4"))


def _edited_model(pt: dict[str, Path], tmp_path: Path, edit) -> Path:
    doc = yaml.load(pt["model"].read_text())
    edit(doc)
    out = tmp_path / "edited.yaml"
    out.write_text(yaml.dump(doc))
    return out


@pytest.mark.parametrize(
    ("edit", "needles"),
    [
        (
            lambda d: d["info"].__setitem__("calibrated_joint_range", [[1.0, 2.0]]),
            ("info.calibrated_joint_range", "expected 6 pairs"),
        ),
        (
            lambda d: d["info"].__setitem__(
                "calibrated_joint_range",
                [[hi, lo] for lo, hi in d["info"]["calibrated_joint_range"]],
            ),
            ("info.calibrated_joint_range[0] (J1)", "lo <= hi"),
        ),
        (
            lambda d: d["info"].__setitem__("calibrated_joint_range", "all"),
            ("info.calibrated_joint_range", "pairs"),
        ),
        (
            lambda d: d["info"].__setitem__("kind", "laser"),
            ("info.kind", "point, pose"),
        ),
        (lambda d: d["info"].__setitem__("kind", "sensor"), ("info.kind", "'point'")),
        (lambda d: d["info"].__setitem__("n", "many"), ("info.n", "positive integer")),
    ],
)
def test_damaged_info_block_is_refused(pt, tmp_path, capsys, edit, needles) -> None:
    """The info block decides the extrapolation warnings and which data evaluate
    accepts: a damaged one was read silently (no warning, or 'calibrated 42 .. -33')."""
    m = _edited_model(pt, tmp_path, edit)
    out = tmp_path / "c.csv"
    for args in (
        ("evaluate", pt["test"], "--model", m, "--json"),
        ("compensate", pt["targets"], "--model", m, "--out", out, "-q"),
        ("fk", "--model", m, "--", "0", "0", "0", "0", "-90", "0"),
    ):
        failed_with(run_kinecal(capsys, *args), str(m), *needles)
    assert not out.exists()


def _with_columns(src: Path, dst: Path, names: str, values: str) -> Path:
    lines = src.read_text().splitlines()
    dst.write_text(
        "\n".join([f"{lines[0]},{names}", *(f"{ln},{values}" for ln in lines[1:])])
        + "\n"
    )
    return dst


def _loaded(src: Path, dst: Path) -> Path:
    """``src`` with a payload_kg column of 1 and 3 kg on alternate rows."""
    lines = src.read_text().splitlines()
    rows = [f"{ln},{1 + 2 * (i % 2)}" for i, ln in enumerate(lines[1:])]
    dst.write_text("\n".join([lines[0] + ",payload_kg", *rows]) + "\n")
    return dst


def _fk_of(doc, tmp_path: Path, capsys, *joints: str):
    """``kinecal fk`` of the robot document ``doc`` written as a file: (file, run)."""
    robot = tmp_path / "robot.yaml"
    robot.write_text(yaml.dump(doc))
    return robot, run_kinecal(capsys, "fk", "--robot", robot, "--", *joints)


@pytest.mark.parametrize("columns", ["qw,qx,qy,qz", "w_deg,p_deg,r_deg"])
def test_constant_orientation_of_turning_poses_is_refused(
    pt, tmp_path, capsys, columns
) -> None:
    """The same orientation on every row while the robot turns the tool (a placeholder
    quaternion): the calibration ran and wrote a model fitted to it."""
    value = "1,0,0,0" if columns.startswith("q") else "0,0,0"
    data = _with_columns(pt["train"], tmp_path / "pose.csv", columns, value)
    out = tmp_path / "cal"
    res = run_kinecal(
        capsys,
        "calibrate",
        data,
        "--robot",
        "fanuc-lrmate200id",
        "--model",
        "kinematic",
        "--cv",
        "off",
        "--out",
        out,
        "-q",
    )
    failed_with(res, str(data), columns.replace(",", ", "), "turns the tool")
    assert not out.exists()


def _joints_out(path: Path) -> list[str]:
    """The corrected joints and predicted errors of a compensate output."""
    lines = path.read_text().splitlines()
    head = lines[0].split(",")
    keep = [i for i, c in enumerate(head) if c.endswith("_deg") or c == "err_mm"]
    keep = [i for i in keep if head[i] not in ("w_deg", "p_deg", "r_deg")]
    return [",".join(ln.split(",")[i] for i in keep) for ln in lines[1:]]


def test_compensate_reads_wpr_orientation_like_quaternions(
    pt, tmp_path, capsys
) -> None:
    """TARGETS with w_deg, p_deg, r_deg: the orientation was dropped silently (position
    only), while the same orientation as qw..qz was compensated."""
    import numpy as np

    from kinecal.geometry import matrix_to_quat_wxyz, wpr_to_matrix

    wpr = (10.0, 20.0, 30.0)
    quat = matrix_to_quat_wxyz(wpr_to_matrix(np.radians(np.array(wpr))))
    files = {
        "wpr": _with_columns(
            pt["targets"],
            tmp_path / "wpr.csv",
            "w_deg,p_deg,r_deg",
            ",".join(map(str, wpr)),
        ),
        "quat": _with_columns(
            pt["targets"],
            tmp_path / "quat.csv",
            "qw,qx,qy,qz",
            ",".join(f"{v:.15f}" for v in quat),
        ),
        "none": pt["targets"],
    }
    got = {}
    for key, f in files.items():
        out = tmp_path / f"{key}.out.csv"
        res = run_kinecal(
            capsys,
            "compensate",
            f,
            "--model",
            pt["model"],
            "--out",
            out,
            "--allow-unreachable",
            "-q",
        )
        assert res.code == 0, str(res)
        got[key] = _joints_out(out)

    def table(key: str):
        return np.array([[float(v) for v in ln.split(",")] for ln in got[key]])

    # The same orientation: the same corrected joints (up to the solver's tolerance
    # on these partly unreachable rows); without the orientation: other joints.
    assert np.abs(table("wpr") - table("quat")).max() < 0.05
    assert np.abs(table("wpr") - table("none")).max() > 1.0


def test_compensate_payload_column(pt, tmp_path, capsys) -> None:
    """A payload_kg column in TARGETS was ignored (the calibration's payload used
    instead); now it is the payload of each row, checked like --payload-kg's."""
    loaded = _loaded(pt["train"], tmp_path / "loaded.csv")
    res = run_kinecal(
        capsys,
        "calibrate",
        loaded,
        "--robot",
        "fanuc-lrmate200id",
        "--model",
        "rfcm",
        "--cv",
        "off",
        "--out",
        tmp_path / "cal",
        "-q",
    )
    assert res.code in (0, 3), str(res)
    model = tmp_path / "cal" / "model.yaml"
    col = _with_columns(pt["targets"], tmp_path / "load.csv", "payload_kg", "6.5")
    a, b, c = (tmp_path / f"{k}.csv" for k in "abc")
    runs = ((col,), (pt["targets"], "--payload-kg", "6.5"), (pt["targets"],))
    for out, args in zip((a, b, c), runs):
        res = run_kinecal(
            capsys, "compensate", *args, "--model", model, "--out", out, "-q"
        )
        assert res.code == 0, str(res)
    assert _joints_out(a) == _joints_out(b) != _joints_out(c)
    res = run_kinecal(
        capsys,
        "compensate",
        col,
        "--model",
        model,
        "--out",
        tmp_path / "d.csv",
        "--payload-kg",
        "1",
        "-q",
    )
    failed_with(res, str(col), "payload_kg", "--payload-kg")
    res = run_kinecal(
        capsys,
        "compensate",
        col,
        "--model",
        pt["model"],
        "--out",
        tmp_path / "e.csv",
        "-q",
    )
    failed_with(res, str(col), "payload_kg", "no reference payload")
    huge = _with_columns(pt["targets"], tmp_path / "huge.csv", "payload_kg", "5000")
    out = tmp_path / "f.csv"
    res = run_kinecal(capsys, "compensate", huge, "--model", model, "--out", out)
    failed_with(res, str(huge), "line 2, column 'payload_kg'", "expected 0 to")
    assert not out.exists()


_PROGRAMS = Path(__file__).resolve().parents[1] / "data" / "programs"


def _cut_line(text: str, needle: str) -> str:
    """``text`` with the first line holding ``needle`` cut in its middle (a copy
    interrupted there) and everything after it gone."""
    at = text.index(needle)
    end = text.find("\n", at)
    return text[: (text.rfind("\n", 0, at) + 1 + end) // 2]


@pytest.mark.parametrize(
    ("name", "cut", "needles"),
    [
        (
            "pick_demo.dat",
            lambda t: _cut_line(t, "XHOME1"),
            ("line 6", "'{' is not closed"),
        ),
        ("pick_demo.dat", lambda t: t.replace("ENDDAT", ""), ("without ENDDAT",)),
        (
            "pick_demo.script",
            lambda t: _cut_line(t, "set_tcp"),
            ("line 2", "not closed"),
        ),
        ("pick_demo.ls", lambda t: t[: t.index("/END")], ("without /END",)),
        ("pick_demo.mod", lambda t: t[: t.index("ENDMODULE")], ("without ENDMODULE",)),
        ("pick_demo.mod", lambda t: t.replace("]]", "]", 1), ("not closed",)),
    ],
)
def test_truncated_program_is_refused(pt, tmp_path, capsys, name, cut, needles) -> None:
    """A program cut short: the target cut in its middle (or the tool set-up) was
    skipped silently and the rest compensated as if the file were whole."""
    prog = tmp_path / f"cut{Path(name).suffix}"
    prog.write_text(cut((_PROGRAMS / name).read_text()))
    out = tmp_path / f"out{Path(name).suffix}"
    res = run_kinecal(
        capsys,
        "compensate",
        prog,
        "--model",
        pt["model"],
        "--out",
        out,
        "--allow-unreachable",
        "-q",
    )
    failed_with(res, str(prog), *needles)
    assert not out.exists()


_FANUC_URDF = (
    Path(__file__).resolve().parents[1]
    / "data"
    / "fanuc_lrmate200id"
    / "fanuc_lrmate200id.urdf"
)


def _j1_limit(text: str, new: str) -> str:
    """The URDF with joint J1's <limit .../> replaced by ``new``."""
    at = text.index('<joint name="J1"')
    a = text.index("<limit", at)
    b = text.index("/>", a) + 2
    return text[:a] + new + text[b:]


@pytest.mark.parametrize(
    ("limit", "needles"),
    [
        ("", ("joint 'J1' (revolute): no <limit>", "continuous")),
        (
            '<limit effort="1" lower="-170" upper="170" velocity="1"/>',
            ("joint 'J1' limit: [-170, 170] rad", "degrees given as radians"),
        ),
    ],
)
def test_urdf_joint_limits_that_cannot_be_right(
    tmp_path, capsys, limit, needles
) -> None:
    """A revolute joint without <limit> was imported as unlimited, one with its limits
    in degrees as +-9740 deg; both are refused by import-urdf and --robot."""
    urdf = tmp_path / "robot.urdf"
    urdf.write_text(_j1_limit(_FANUC_URDF.read_text(), limit))
    out = tmp_path / "robot.yaml"
    failed_with(
        run_kinecal(capsys, "import-urdf", urdf, "--out", out), str(urdf), *needles
    )
    sim = tmp_path / "sim"
    failed_with(
        run_kinecal(capsys, "simulate", "--robot", urdf, "--out", sim, "-q"),
        str(urdf),
        *needles,
    )
    assert not out.exists() and not sim.exists()


def test_robot_yaml_limits_in_the_wrong_unit(tmp_path, capsys) -> None:
    """A robot file in radians with its limits typed in degrees: +-170 rad was taken
    as a joint that turns 27 times each way."""
    from kinecal.robot import dump_robot, load_robot

    doc = dump_robot(load_robot("generic-6r"))
    doc["units"]["angle"] = "rad"
    for j in doc["joints"]:
        for k in ("theta_offset", "alpha"):
            j[k] = j[k] * 3.141592653589793 / 180
    doc["joints"][0]["limits"] = [-170, 170]
    robot, res = _fk_of(doc, tmp_path, capsys, "0", "0", "0", "0", "0", "0")
    failed_with(res, str(robot), "joints[0].limits", "degrees given as radians")


def test_link_length_in_metres_is_refused(pt, tmp_path, capsys) -> None:
    """joint2.a typed in metres (0.33 for 330 mm) is 330 mm off a 330 mm link, within
    the old bound (half the robot's reach, 415 mm): fk and export-urdf used it."""

    def edit(d) -> None:
        d["parameters"]["joint2.a"]["value"] = (
            d["parameters"]["joint2.a"]["value"] / 1e3
        )

    m = _edited_model(pt, tmp_path, edit)
    out = tmp_path / "cal.urdf"
    for args in (
        ("fk", "--model", m, "--", "0", "0", "0", "0", "-90", "0"),
        ("export-urdf", m, "--out", out),
    ):
        failed_with(
            run_kinecal(capsys, *args), str(m), "parameters.joint2.a", "165 to 495"
        )
    assert not out.exists()


@pytest.mark.parametrize("radius", ["-14.999", "0"])
def test_targets_radius_not_positive_is_refused(tmp_path, radius) -> None:
    """A targets file's r_mm of -15 or 0 was read as a sphere radius."""
    from kinecal.errors import DataError
    from kinecal.io import read_targets

    f = tmp_path / "targets.csv"
    f.write_text(
        "target,x_mm,y_mm,z_mm,r_mm\nS1,185.3,408.4,2303.9,15.0\n"
        f"S2,240.4,377.9,2640.9,{radius}\n"
    )
    with pytest.raises(DataError, match=r"line 3, column 'r_mm': .*expected a sphere"):
        read_targets(f)


@pytest.mark.parametrize("tag", ["origin", "axis", "limit"])
def test_urdf_element_given_twice_is_refused(tmp_path, capsys, tag) -> None:
    """A second <origin>, <axis> or <limit> in a joint (an edit pasted beside the
    original): the first was used and the other ignored, whichever the user meant."""
    extra = {
        "origin": '<origin xyz="1 2 3"/>',
        "axis": '<axis xyz="1 0 0"/>',
        "limit": '<limit lower="-1" upper="1" effort="1" velocity="1"/>',
    }[tag]
    head = '<joint name="J2" type="revolute">'
    urdf = tmp_path / "robot.urdf"
    urdf.write_text(_FANUC_URDF.read_text().replace(head, head + extra))
    out = tmp_path / "robot.yaml"
    res = run_kinecal(capsys, "import-urdf", urdf, "--out", out)
    failed_with(res, str(urdf), f"joint 'J2' has 2 <{tag}> elements", "at most one")
    assert not out.exists()


@pytest.mark.parametrize(
    ("where", "value"), [("name", "lr\nmate"), ("joint", "J1\u202e"), ("name", "a\tb")]
)
def test_robot_names_must_be_one_printable_line(tmp_path, capsys, where, value) -> None:
    """A robot or joint name with a line break, tab or text-direction character was
    accepted and written into file headers, URDFs and reports."""
    from kinecal.robot import dump_robot, load_robot

    doc = dump_robot(load_robot("fanuc-lrmate200id"))
    if where == "name":
        doc["name"] = value
    else:
        doc["joints"][0]["name"] = value
    robot, res = _fk_of(doc, tmp_path, capsys, "0", "0", "0", "0", "-90", "0")
    failed_with(res, str(robot), "name", "one-line string")


def test_compensate_targets_in_metres_are_refused(pt, tmp_path, capsys) -> None:
    """x_mm, y_mm, z_mm holding metres: compensate called every target unreachable
    (exit 4) instead of naming the unit, as evaluate and calibrate do (exit 2)."""
    lines = pt["targets"].read_text().splitlines()
    head = lines[0].split(",")
    k = [head.index(c) for c in ("x_mm", "y_mm", "z_mm")]
    rows = []
    for ln in lines[1:]:
        c = ln.split(",")
        for i in k:
            c[i] = f"{float(c[i]) / 1e3:.9f}"
        rows.append(",".join(c))
    f = tmp_path / "metres.csv"
    f.write_text("\n".join([lines[0], *rows]) + "\n")
    out = tmp_path / "c.csv"
    res = run_kinecal(capsys, "compensate", f, "--model", pt["model"], "--out", out)
    failed_with(res, str(f), "columns x_mm, y_mm, z_mm", "looks like metres")
    assert not out.exists()


def test_fit_of_another_robots_data_is_refused_naming_the_data(
    pt, tmp_path, capsys
) -> None:
    """LR Mate data calibrated as a UR5e: calibrate failed on reading back its own
    model.yaml (the message named the result file), compare printed the table (exit 0)."""
    out = tmp_path / "cal"
    res = run_kinecal(capsys, "calibrate", pt["train"], "--robot", "ur5e", "--model",
                      "kinematic", "--cv", "off", "--out", out, "-q")  # fmt: skip
    last = failed_with(res, str(pt["train"]), "fit ends with", "ur5e")
    assert "model.yaml" not in last and not out.exists()
    res = run_kinecal(capsys, "compare", pt["train"], pt["test"], "--robot", "ur5e",
                      "--models", "kinematic", "-q")  # fmt: skip
    failed_with(res, str(pt["train"]), "fit ends with", "another robot")


@pytest.mark.parametrize("cmd", ["compensate", "fk"])
def test_payload_option_beyond_ten_times_rating(pt, tmp_path, capsys, cmd) -> None:
    """--payload-kg 5000 on a 7 kg robot was accepted (kg typed as g)."""
    tail = ("--", "0", "0", "0", "0", "-90", "0")
    args = (
        ("compensate", pt["targets"], "--out", tmp_path / "c.csv")
        if cmd == "compensate"
        else ("fk",)
    )
    res = run_kinecal(capsys, *args, "--model", pt["model"], "--payload-kg", "5000",
                      *(tail if cmd == "fk" else ()))  # fmt: skip
    failed_with(res, "--payload-kg 5000", "at most 70 kg")


def test_calibrated_payload_beyond_ten_times_rating_names_the_data(
    pt, tmp_path, capsys
) -> None:
    """payload_kg 5000 (grams typed as kg) on a 7 kg robot: calibrate failed on reading
    back its own model.yaml, and the message named that file, not the data."""
    data = _with_columns(pt["train"], tmp_path / "heavy.csv", "payload_kg", "5000")
    out = tmp_path / "cal"
    res = run_kinecal(capsys, "calibrate", data, "--robot", "fanuc-lrmate200id",
                      "--model", "rfcm", "--cv", "off", "--out", out, "-q")  # fmt: skip
    last = failed_with(res, str(data), "payload_kg: 5000 kg", "up to 70 kg")
    assert "model.yaml" not in last and not out.exists()


def test_export_like_vendor_limits_in_degrees_is_refused(tmp_path, capsys) -> None:
    """export-urdf --like keeps the vendor's limits: a vendor file with J1's lower
    limit typed in degrees (-170 'rad') was copied into the calibrated URDF."""
    robot, sim, cal = tmp_path / "robot.yaml", tmp_path / "sim", tmp_path / "cal"
    for args in (
        ("import-urdf", _FANUC_URDF, "--out", robot),
        ("simulate", "--robot", robot, "--out", sim, "-q"),
        ("calibrate", sim / "train.csv", "--robot", robot, "--model", "kinematic",
         "--cv", "off", "--out", cal, "-q"),
    ):  # fmt: skip
        res = run_kinecal(capsys, *args)
        assert res.code == 0, str(res)
    vendor = tmp_path / "vendor.urdf"
    vendor.write_text(
        _j1_limit(
            _FANUC_URDF.read_text(),
            '<limit effort="500" lower="-170" upper="3.14" velocity="7.85"/>',
        )
    )
    out = tmp_path / "like.urdf"
    res = run_kinecal(capsys, "export-urdf", cal / "model.yaml", "--like", vendor,
                      "--out", out)  # fmt: skip
    failed_with(res, str(vendor), "joint 'J1' limit", "degrees given as radians")
    assert not out.exists()


@pytest.mark.parametrize(
    ("columns", "values", "needles"),
    [
        ("w_deg,p_deg", "0,0", ("missing column 'r_deg'",)),
        ("qw,qx,qy,qz,w_deg,p_deg,r_deg", "1,0,0,0,0,0,0", ("either as qw..qz",)),
    ],
)
def test_compensate_partial_or_double_orientation(
    pt, tmp_path, capsys, columns, values, needles
) -> None:
    """Two of w_deg, p_deg, r_deg (or both spellings) in TARGETS were ignored."""
    f = _with_columns(pt["targets"], tmp_path / "t.csv", columns, values)
    out = tmp_path / "c.csv"
    res = run_kinecal(capsys, "compensate", f, "--model", pt["model"], "--out", out)
    failed_with(res, str(f), *needles)
    assert not out.exists()


def test_plan_joint_range_beyond_the_limits_is_refused(tmp_path, capsys) -> None:
    """--joint-range J1:-500:500 on a +-170 deg joint was clipped to the limits
    silently (a range in the wrong unit or for another robot)."""
    out = tmp_path / "plan.csv"
    res = run_kinecal(capsys, "plan", "--robot", "fanuc-lrmate200id", "--model",
                      "kinematic", "--poses", "30", "--joint-range", "J1:-500:500",
                      "--out", out)  # fmt: skip
    failed_with(res, "--joint-range", "J1's limits [-170, 170] deg")
    assert not out.exists()


def test_evaluate_payload_column_without_reference_payload(
    pt, tmp_path, capsys
) -> None:
    """A model with payload compliance but no reference payload (calibrated on data
    without payload_kg) scaled its compliance by the evaluated data's own mean payload;
    now refused, as compensate's TARGETS are. Data without the column still evaluate."""
    loaded = _loaded(pt["train"], tmp_path / "loaded.csv")
    res = run_kinecal(capsys, "evaluate", loaded, "--model", pt["model"])
    failed_with(res, str(loaded), "payload_kg", "no reference payload")
    res = run_kinecal(capsys, "evaluate", pt["train"], "--model", pt["model"])
    assert res.code == 0, str(res)
