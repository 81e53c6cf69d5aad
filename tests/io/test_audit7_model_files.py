"""Audit 7: a model.yaml handed back to kinecal, edited or damaged by hand. Each case
exits 2 with one Error line naming the file and the key (never a traceback, a 2 GB
message or an internal error), and a hand-typed number in exponent notation reads."""

from __future__ import annotations

import pytest

from kinecal import _yaml as yaml
from kinecal.errors import ConfigError
from kinecal.io import load_model
from tests.cli_contract import failed_with, make_point_data, run_kinecal

FK = ["0", "0", "0", "0", "-90", "0"]


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    return make_point_data(tmp_path_factory.mktemp("audit7"))


def _text(data):
    return data["model"].read_text()


def _write(tmp_path, text):
    f = tmp_path / "model.yaml"
    f.write_text(text)
    return f


def _bomb(levels=9):
    """A "billion laughs": 10 aliases of a list of 10 aliases of ... (10**levels)."""
    lines = ["  b0: &a0 [lol, lol, lol, lol, lol, lol, lol, lol, lol, lol]"]
    for i in range(1, levels):
        lines.append(f"  b{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 10) + "]")
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("command", ["fk", "evaluate"])
def test_alias_bomb_in_the_info_block_is_refused(data, capsys, tmp_path, command):
    text = _text(data).replace("info:\n", "info:\n" + _bomb(), 1)
    text = text.replace("\n  source: ", "\n  source: *a8\n  was: ", 1)
    m = _write(tmp_path, text)
    args = {
        "fk": ["fk", "--model", m, "--json", "--", *FK],
        "evaluate": ["evaluate", data["test"], "--model", m, "--json"],
    }[command]
    res = run_kinecal(capsys, *args)
    line = failed_with(res, str(m), "aliases", "billion laughs")
    assert len(res.err) < 2000, len(res.err)  # was: the expanded list, 2 GB
    assert line


def test_alias_bomb_in_a_robot_file_is_refused(capsys, tmp_path):
    robot = tmp_path / "robot.yaml"
    robot.write_text(
        "name: r\nconvention: dh\nunits: {length: mm, angle: deg}\n"
        "description:\n" + _bomb().replace("  b", "  - b").replace(": &", ": &")
    )
    res = run_kinecal(capsys, "fk", "--robot", robot, "--json", "--", *FK)
    failed_with(res, "robot.yaml", "aliases")


def test_a_recursive_alias_is_refused():
    with pytest.raises(yaml.YAMLError, match="recursive"):
        yaml.load("a: &x [1, *x]\n")


def test_aliases_of_a_plain_file_still_read():
    doc = yaml.load("lim: &l [-170, 170]\njoints: [{limits: *l}, {limits: *l}]\n")
    assert doc["joints"][1]["limits"] == [-170, 170]


def _edit_param(text, name, key, new):
    """The text with ``key`` of parameter ``name`` replaced by ``new`` (YAML text)."""
    head = text.index(f"\n  {name}:\n")
    start = text.index(f"    {key}: ", head)
    end = text.index("\n", start)
    return text[:start] + f"    {key}: {new}" + text[end:]


def _first_estimated(text):
    doc = yaml.load(text)
    return next(
        n
        for n, p in doc["parameters"].items()
        if p["status"] == "estimated" and p["unit"] == "mm" and n.startswith("joint")
    )


@pytest.mark.parametrize(
    "key, new, needles",
    [
        ("status", "unidentifiable", [".std", "status is 'unidentifiable'", "null"]),
        ("status", "fixed", [".std", "status is 'fixed'", "expected null"]),
    ],
)
def test_std_that_cannot_be_right_is_refused(data, capsys, tmp_path, key, new, needles):
    """A std beside a status that says the data did not determine the parameter
    (kinecal writes null) was taken by every command."""
    text = _text(data)
    name = _first_estimated(text)
    m = _write(tmp_path, _edit_param(text, name, key, new))
    res = run_kinecal(
        capsys, "plan", "--model", m, "--add", "3", "--candidates", data["test"],
        "--out", tmp_path / "plan.csv",
    )  # fmt: skip
    failed_with(res, str(m), f"parameters.{name}", *needles)
    assert not (tmp_path / "plan.csv").exists()


def test_plan_add_on_a_huge_std(data, capsys, tmp_path):
    """A std of 1e300 mm (an undetermined parameter; kinecal itself writes 9e6 mm for
    a marker seen in one pose) made plan --add fail with an internal error (a
    singular information matrix): it carries no more than the prior's information."""
    text = _text(data)
    name = _first_estimated(text)
    m = _write(tmp_path, _edit_param(text, name, "std", "1.0e+300"))
    res = run_kinecal(
        capsys, "plan", "--model", m, "--add", "3", "--candidates", data["test"],
        "--out", tmp_path / "plan.csv",
    )  # fmt: skip
    assert res.code == 0, str(res)
    assert (tmp_path / "plan.csv").is_file()


def test_status_without_std_still_reads(data, tmp_path):
    text = _text(data)
    name = _first_estimated(text)
    text = _edit_param(_edit_param(text, name, "std", "null"), name, "status", "fixed")
    load_model(_write(tmp_path, text))


@pytest.mark.parametrize(
    "line, needles",
    [
        ("kinecal_model: true", ["model format True", "expected 1"]),
        ("kinecal_version: [0, 1]", ["kinecal_version: list", "one line of text"]),
        ("kinecal_version: 2024-01-01", ["kinecal_version: date"]),
        ("kinecal_version: !!binary aGVsbG8=", ["kinecal_version: bytes"]),
    ],
)
def test_retyped_header_keys_are_refused(data, tmp_path, line, needles):
    text = _text(data)
    key = line.split(":")[0]
    start = text.index(f"\n{key}: ") + 1
    end = text.index("\n", start)
    m = _write(tmp_path, text[:start] + line + text[end:])
    with pytest.raises(ConfigError) as err:
        load_model(m)
    for n in [str(m), *needles]:
        assert n in str(err.value)


def test_info_source_of_another_type_is_refused(data, tmp_path):
    text = _text(data).replace("\n  source: ", "\n  source: [1, 2]\n  was: ", 1)
    with pytest.raises(ConfigError, match=r"info\.source: list; expected one line"):
        load_model(_write(tmp_path, text))


def test_hand_typed_exponent_numbers_read(data, tmp_path):
    """A std typed as 1e-3 (YAML 1.2's number) was refused: "expected a finite
    number; got '1e-3'" (the file was read as YAML 1.1, where it is a string)."""
    text = _text(data)
    name = _first_estimated(text)
    cal = load_model(_write(tmp_path, _edit_param(text, name, "std", "2e-3")))
    i = cal.model.layout.names.index(name)
    assert cal.std[i] == pytest.approx(2e-6)  # 2e-3 mm in metres


def test_an_old_fingerprint_that_looks_like_a_number_still_matches(data, tmp_path):
    """Earlier versions wrote a fingerprint such as 1234e56789012345 unquoted: read as
    YAML 1.2 it is a number; the text as written is compared."""
    from kinecal.io._model_checks import stamp_as_written

    doc = {"robot_sha256": 1.234e300}
    text = "robot_sha256: 1234e300\nx: 1\n"
    assert stamp_as_written(doc, text)["robot_sha256"] == "1234e300"


@pytest.mark.parametrize("pair", ["[-1000.0, 1000.0]", "[-600, 10]", "[10, 900]"])
def test_calibrated_range_beyond_the_limits_is_refused(data, tmp_path, pair):
    """A range a turn beyond the joint's limits (the data may hold at most that, with
    --allow-out-of-limits) silenced the warnings for poses outside the calibrated
    ranges; J1 of the LR Mate turns within [-170, 170] deg."""
    doc = yaml.load(_text(data))
    doc["info"]["calibrated_joint_range"][0] = yaml.load(pair)
    m = _write(tmp_path, yaml.dump(doc, sort_keys=False))
    with pytest.raises(ConfigError) as err:
        load_model(m)
    for n in [str(m), "info.calibrated_joint_range[0]", "limits [-170, 170] deg"]:
        assert n in str(err.value), str(err.value)


def test_calibrated_range_a_little_beyond_the_limits_reads(data, tmp_path):
    doc = yaml.load(_text(data))
    doc["info"]["calibrated_joint_range"][0] = [-175.0, 172.0]
    load_model(_write(tmp_path, yaml.dump(doc, sort_keys=False)))
