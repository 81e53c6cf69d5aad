"""Audit 7: URDFs handed to kinecal (``--robot X.urdf``, ``import-urdf``, ``export-urdf
--like``) with values that parse but cannot be right: exit 2 naming the file, the
element and the value expected, as the robot YAML's checks do."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.cli_contract import failed_with, run_kinecal

URDF = (
    Path(__file__).parents[1] / "data" / "fanuc_lrmate200id" / "fanuc_lrmate200id.urdf"
)
FK = ["0", "0", "0", "0", "0", "0"]


def _joint_edit(text: str, joint: str, old: str, new: str) -> str:
    i = text.index(f'<joint name="{joint}"')
    j = text.index("</joint>", i)
    assert old in text[i:j]
    return text[:i] + text[i:j].replace(old, new, 1) + text[j:]


def _write(tmp_path: Path, text: str) -> Path:
    f = tmp_path / "robot.urdf"
    f.write_text(text)
    return f


def _commands(f: Path, tmp_path: Path) -> dict[str, list[object]]:
    return {
        "fk": ["fk", "--robot", f, "--json", "--", *FK],
        "import-urdf": ["import-urdf", f, "--out", tmp_path / "robot.yaml"],
    }


@pytest.mark.parametrize("command", ["fk", "import-urdf"])
@pytest.mark.parametrize("rpy", ["0 0 90", "0 -180 0", "0 0 1e20"])
def test_joint_rpy_in_degrees_is_refused(capsys, tmp_path, command, rpy):
    """rpy="0 0 90" (degrees for radians) read as 90 rad = 14.3 turns: another
    rotation, without a word."""
    text = _joint_edit(URDF.read_text(), "J2", 'rpy="0 0 0"', f'rpy="{rpy}"')
    f = _write(tmp_path, text)
    res = run_kinecal(capsys, *_commands(f, tmp_path)[command])
    failed_with(res, str(f), "joint 'J2' origin rpy", "rad", "degrees given as radians")
    assert not (tmp_path / "robot.yaml").exists()


def test_a_turn_rounded_up_still_reads(capsys, tmp_path):
    text = _joint_edit(URDF.read_text(), "J2", 'rpy="0 0 0"', 'rpy="0 0 6.2832"')
    res = run_kinecal(capsys, *_commands(_write(tmp_path, text), tmp_path)["fk"])
    assert res.code == 0, str(res)


@pytest.mark.parametrize("command", ["fk", "import-urdf"])
def test_a_document_that_is_not_a_robot_is_refused(capsys, tmp_path, command):
    """An <sdf> (or any other root) read as a robot named 'robot' with its joints."""
    text = URDF.read_text().replace('<robot name="lrmate200id">', "<sdf>")
    f = _write(tmp_path, text.replace("</robot>", "</sdf>"))
    res = run_kinecal(capsys, *_commands(f, tmp_path)[command])
    failed_with(res, str(f), "expected a URDF <robot> document", "got <sdf>")


@pytest.mark.parametrize("command", ["fk", "import-urdf"])
def test_a_link_mass_beyond_the_robot_files_bound_is_refused(capsys, tmp_path, command):
    """import-urdf refused a link of 9e9 kg (the robot file's bound, 10000 kg), but
    --robot X.urdf took it."""
    text = URDF.read_text().replace('<mass value=" 9.05"/>', '<mass value="9e9"/>')
    f = _write(tmp_path, text)
    res = run_kinecal(capsys, *_commands(f, tmp_path)[command])
    failed_with(res, str(f), "link 'J2_link' inertial mass", "0..10000 kg", "9e+09")


def test_like_a_vendor_revolute_joint_without_limits_is_refused(capsys, tmp_path):
    """import-urdf refused it; export-urdf --like wrote the calibrated copy, a URDF
    that urdfdom refuses (a revolute joint needs its limits)."""
    from tests.cli_contract import make_point_data

    data = make_point_data(tmp_path)
    text = URDF.read_text()
    i = text.index('<joint name="J2"')
    a = text.index("<limit", i)
    b = text.index("/>", a) + 2
    f = _write(tmp_path, text[:a] + text[b:])
    out = tmp_path / "cal.urdf"
    res = run_kinecal(capsys, "export-urdf", data["model"], "--like", f, "--out", out)
    failed_with(res, str(f), "joint 'J2' (revolute): no <limit>", "continuous")
    assert not out.exists()


def test_like_the_vendor_file_as_it_is(capsys, tmp_path):
    from tests.cli_contract import make_point_data

    data = make_point_data(tmp_path)
    out = tmp_path / "cal.urdf"
    res = run_kinecal(
        capsys, "export-urdf", data["model"], "--like", URDF, "--out", out
    )
    assert res.code == 0, str(res)


@pytest.mark.parametrize(
    "args, needles",
    [
        (["--tip", "tool0"], ["no link 'tool0' (--tip)", "12 links: J1_link, J2_link"]),
        (["--base", "base"], ["no link 'base' (--base)", "expected one of"]),
        (
            ["--base", "J3_link", "--tip", "J1_link"],
            ["'J1_link' is not below link 'J3_link'", "goes up to 'world'"],
        ),
    ],
)
def test_a_wrong_base_or_tip_link_names_the_links(capsys, tmp_path, args, needles):
    """The message named the missing link only ("no link 'tool0' (tip).")."""
    out = tmp_path / "robot.yaml"
    res = run_kinecal(capsys, "import-urdf", URDF, *args, "--out", out)
    failed_with(res, str(URDF), *needles)
    assert not out.exists()


@pytest.mark.parametrize("encoding", ["utf-16", "latin-1"])
def test_like_a_vendor_file_not_in_utf8_says_so(capsys, tmp_path, encoding):
    """The message was the codec's ("'utf-8' codec can't decode byte 0xff ...")."""
    from tests.cli_contract import make_point_data

    data = make_point_data(tmp_path)
    text = URDF.read_text().replace("<!-- links -->", "<!-- caf\xe9 -->")
    if encoding == "utf-16":
        text = text.replace(
            '<?xml version="1.0" ?>', '<?xml version="1.0" encoding="UTF-16"?>'
        )
    f = tmp_path / "robot.urdf"
    f.write_bytes(text.encode(encoding))
    out = tmp_path / "cal.urdf"
    res = run_kinecal(capsys, "export-urdf", data["model"], "--like", f, "--out", out)
    failed_with(res, str(f), "not UTF-8 text", "save it as UTF-8")
    assert not out.exists()
