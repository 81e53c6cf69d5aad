"""Audit 9: URDF files a user hands kinecal (--robot, import-urdf, export-urdf --like) go
through one gate (kinecal.robot._urdf_read): entities, xacro leftovers, encodings,
folders, empty and huge files are refused naming the file and line; the document is
parsed in one piece (a 40 MB comment took 13 s, 200 MB did not end)."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from kinecal.errors import ConfigError
from kinecal.robot import load_robot, robot_from_urdf
from kinecal.robot._urdf_read import MAX_URDF_BYTES
from tests.cli_contract import failed_with, run_kinecal

# (name, parent, child, xyz, rpy, axis, lower, upper): a small 6R arm in metres
_JOINTS = [
    ("j1", "base_link", "l1", "0 0 0.15", "0 0 0", "0 0 1"),
    ("j2", "l1", "l2", "0 0.1 0", "0 1.5708 0", "0 1 0"),
    ("j3", "l2", "l3", "0 -0.1 0.4", "0 0 0", "0 1 0"),
    ("j4", "l3", "l4", "0 0 0.39", "0 1.5708 0", "0 1 0"),
    ("j5", "l4", "l5", "0 0.1 0", "0 0 0", "0 0 1"),
    ("j6", "l5", "l6", "0 0 0.09", "0 0 0", "0 1 0"),
]


def _urdf(head: str = '<?xml version="1.0"?>\n', name: str = "arm", **edit) -> str:
    """The arm's URDF; ``edit``: joint name -> {field: text} (xyz, rpy, axis, lower)."""
    links = ["base_link"] + [j[2] for j in _JOINTS]
    s = head + f'<robot name="{name}">\n'
    s += "".join(f'  <link name="{lk}"/>\n' for lk in links)
    for jn, p, c, xyz, rpy, axis in _JOINTS:
        f = {"xyz": xyz, "rpy": rpy, "axis": axis, "lower": "-3", "upper": "3"}
        f.update(edit.get(jn, {}))
        s += (
            f'  <joint name="{jn}" type="revolute"><parent link="{p}"/>'
            f'<child link="{c}"/><origin xyz="{f["xyz"]}" rpy="{f["rpy"]}"/>'
            f'<axis xyz="{f["axis"]}"/><limit lower="{f["lower"]}" '
            f'upper="{f["upper"]}" effort="10" velocity="2"/></joint>\n'
        )
    return s + "</robot>\n"


def _write(tmp_path: Path, text: str | bytes, name: str = "arm.urdf") -> Path:
    p = tmp_path / name
    if isinstance(text, bytes):
        p.write_bytes(text)
    else:
        p.write_text(text, encoding="utf-8")
    return p


_LAUGHS = (
    '<?xml version="1.0"?>\n<!DOCTYPE robot [<!ENTITY a "aaaaaaaaaa">'
    + "".join(
        f'<!ENTITY a{i} "{("&a" + str(i - 1) if i else "&a") + ";"}'
        f'{("&a" + str(i - 1) if i else "&a") + ";"}">'
        for i in range(8)
    )
    + "]>\n"
)


@pytest.mark.parametrize(
    "text, needles",
    [
        (_urdf(head=_LAUGHS, name="&a7;"), ["line 2:", "XML entity 'a'"]),
        (
            _urdf(
                head='<?xml version="1.0"?>\n<!DOCTYPE r [\n<!ENTITY x SYSTEM '
                '"file:///etc/passwd">]>\n',
                name="&x;",
            ),
            ["line 3:", "XML entity 'x'"],
        ),
        (
            _urdf(j2={"xyz": "0 ${shoulder_offset} 0"}),
            ["line 11:", "'${shoulder_offset}' is a xacro expression", "xacro FILE"],
        ),
        (_urdf(j3={"lower": "${-pi}"}), ["'${-pi}' is a xacro expression"]),
        (
            _urdf().replace(
                "</robot>", '<xacro:property name="a" value="1"/>\n</robot>'
            ),
            ["line 16:", "a xacro element without the xacro namespace"],
        ),
        ("", ["the file is empty"]),
        ("  \n\n", ["the file is empty"]),
        (
            _urdf(name="bras_\xe9").encode("latin-1"),
            ["line 2: byte 0xe9 is not UTF-8", "save it as UTF-8"],
        ),
    ],
)
def test_bad_urdf_documents_are_named(tmp_path, capsys, text, needles):
    p = _write(tmp_path, text)
    for args in (
        ("fk", "--robot", p, "0", "0", "0", "0", "0", "0"),
        ("import-urdf", p, "--out", tmp_path / "r.yaml"),
    ):
        failed_with(run_kinecal(capsys, *args), str(p), *needles)
    assert not (tmp_path / "r.yaml").exists()


def test_a_comment_in_a_xacro_example_is_no_expression(tmp_path):
    text = _urdf().replace("<robot", "<!-- was: ${shoulder_offset} -->\n<robot")
    assert load_robot(_write(tmp_path, text)).n_joints == 6


def test_encodings_the_xml_declares_still_read(tmp_path):
    latin = '<?xml version="1.0" encoding="ISO-8859-1"?>\n'
    p = _write(tmp_path, _urdf(head=latin, name="bras_\xe9").encode("latin-1"))
    assert robot_from_urdf(p).name == "bras_\xe9"
    utf16 = '<?xml version="1.0" encoding="UTF-16"?>\n'
    p = _write(tmp_path, _urdf(head=utf16).encode("utf-16"), "u16.urdf")
    assert robot_from_urdf(p).n_joints == 6
    p = _write(tmp_path, b"\xef\xbb\xbf" + _urdf().encode(), "bom.urdf")
    assert robot_from_urdf(p).n_joints == 6


def test_a_folder_and_a_huge_file(tmp_path, monkeypatch):
    d = tmp_path / "arm.urdf"
    d.mkdir()
    with pytest.raises(ConfigError, match=r"arm.urdf: is a folder; expected a URDF"):
        load_robot(d)
    big = _urdf().replace("</robot>", "<!--" + "x" * 3_000_000 + "-->\n</robot>")
    p = _write(tmp_path, big, "big.urdf")
    t0 = time.perf_counter()
    assert robot_from_urdf(p).n_joints == 6  # one long token: parsed in one piece
    assert time.perf_counter() - t0 < 1.0
    monkeypatch.setattr("kinecal.robot._urdf_read.MAX_URDF_BYTES", 1 << 20)
    with pytest.raises(ConfigError, match=r"big.urdf: 2.9 MB; expected a URDF"):
        robot_from_urdf(p)
    assert MAX_URDF_BYTES >= 16 << 20  # real URDFs are far smaller


def test_a_urdf_without_its_extension_is_read_as_one(tmp_path, capsys):
    p = _write(tmp_path, _urdf(), "arm_robot")
    # was: "expected a mapping; got str" (the XML read as YAML)
    assert load_robot(p).n_joints == 6
    res = run_kinecal(capsys, "fk", "--robot", p, "0", "0", "0", "0", "0", "0")
    assert res.code == 0, str(res)


def test_infinite_limits_say_continuous(tmp_path):
    p = _write(tmp_path, _urdf(j3={"lower": "-inf", "upper": "inf"}))
    with pytest.raises(ConfigError, match=r"joint 'j3' limit: expected finite limits.*"
                       r"type 'continuous'"):  # fmt: skip
        robot_from_urdf(p)


def test_axes_a_hair_from_parallel_are_named(tmp_path, capsys):
    # j3's axis tilted by 1 mrad from j2's: the common normal 400 m away. fk --robot
    # read d = -400 m without a word; 1e-7 (d = 4000 km) is beyond any robot file.
    p = _write(tmp_path, _urdf(j3={"axis": "0 1 0.001"}))
    res = run_kinecal(capsys, "fk", "--robot", p, "0", "0", "0", "0", "0", "0")
    assert res.code == 0, str(res)
    assert res.err.count("warning") == 1, res.err  # the first far row only
    assert "axes of joints 'j2' and 'j3' are 0.0573 deg from parallel" in res.err
    assert "d = -400 m" in res.err
    p = _write(tmp_path, _urdf(j3={"axis": "0 1 1e-7"}))
    failed_with(
        run_kinecal(capsys, "fk", "--robot", p, "0", "0", "0", "0", "0", "0"),
        "axes of joints 'j2' and 'j3' are 5.73e-06 deg from parallel",
        "d = -4e+06 m",
        "meet within 10000 m",
    )
    res = run_kinecal(capsys, "fk", "--robot", _write(tmp_path, _urdf()), "0", "0",
                      "0", "0", "0", "0")  # fmt: skip
    assert res.code == 0 and "parallel" not in res.err, str(res)


def test_far_axes_name_themselves_when_their_masses_are_refused(tmp_path):
    # with inertials, the centre of mass lies in the DH frame 400 m away: the robot
    # file's check refused it as 'check units.length'
    text = _urdf(j3={"axis": "0 1 0.001"}).replace(
        '<link name="l2"/>',
        '<link name="l2"><inertial><mass value="5"/></inertial></link>',
    )
    with pytest.raises(ConfigError, match=r"axes of joints 'j2' and 'j3' are 0.0573 "
                       r"deg from parallel.*refused: link_masses"):  # fmt: skip
        with pytest.warns(UserWarning, match="from parallel"):
            robot_from_urdf(_write(tmp_path, text))


def test_unsupported_joint_types_say_what_is_read(tmp_path):
    text = _urdf().replace('name="j4" type="revolute"', 'name="j4" type="planar"')
    with pytest.raises(ConfigError, match=r"joint 'j4' has unsupported type 'planar'; "
                       r"expected revolute, continuous, prismatic or fixed"):  # fmt: skip
        robot_from_urdf(_write(tmp_path, text))


def test_export_like_goes_through_the_same_gate(tmp_path):
    from kinecal.io._urdf_like_steps import read_vendor

    for text, match in (
        (_urdf(head=_LAUGHS, name="&a7;"), r"line 2: declares the XML entity 'a'"),
        (_urdf(j2={"xyz": "0 ${d} 0"}), r"'\$\{d\}' is a xacro expression"),
    ):
        p = _write(tmp_path, text)
        with pytest.raises(ConfigError, match=match):
            read_vendor(p, None)
    assert read_vendor(_write(tmp_path, _urdf()), None)[1].tag == "robot"
    latin = '<?xml version="1.0" encoding="ISO-8859-1"?>\n'
    p = _write(tmp_path, _urdf(head=latin, name="bras_\xe9").encode("latin-1"))
    # its text is written back: UTF-8 only, the line named (was: 'byte 61')
    with pytest.raises(ConfigError, match=r"line 2: not UTF-8 text \(byte 0xe9\)"):
        read_vendor(p, None)


def test_a_urdf_passes_the_robot_files_checks(tmp_path):
    """--robot X.urdf took what import-urdf's YAML refuses: a coupling factor of 1e300
    (a kinecal coupling line, a mimic multiplier) moved J3 by 1e300 J2."""
    text = _urdf().replace(
        "</robot>", "<!-- kinecal coupling (theta = C q_ctrl): J3 += 1e300 * J2 -->\n"
        "</robot>"
    )  # fmt: skip
    with pytest.raises(ConfigError, match=r"arm.urdf: coupling\[0\].factor: 1e\+300; "
                       r"expected a coupling factor within"):  # fmt: skip
        load_robot(_write(tmp_path, text))
    ok = text.replace("1e300 * J2", "1.0 * J2")
    assert load_robot(_write(tmp_path, ok)).coupling[2, 1] == 1.0


def test_links_without_names(tmp_path):
    """A <link/> without a name and joints whose <parent/> / <child/> name no link
    matched each other (the empty name): read as a robot (urdfdom refuses both)."""
    text = _urdf().replace('<link name="l3"/>', "<link/>")
    with pytest.raises(ConfigError, match=r"link 4 \(in file order\) has no name"):
        robot_from_urdf(_write(tmp_path, text))
    text = _urdf().replace('<child link="l3"/>', "<child/>")
    with pytest.raises(ConfigError, match=r"joint 'j3': <child> names no link"):
        robot_from_urdf(_write(tmp_path, text))


def test_a_urdf_argument_that_is_no_xml(tmp_path, capsys):
    p = _write(tmp_path, "name: arm\nconvention: dh\n", "robot.urdf")
    res = run_kinecal(capsys, "import-urdf", p, "--out", tmp_path / "r.yaml")
    # was: 'cannot read URDF (not well-formed (invalid token): line 1, column 4)'
    failed_with(res, "robot.urdf: not an XML document (it starts with 'name: arm')")
