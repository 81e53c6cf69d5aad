"""Issue 35 (1): a model file is untrusted input. Every parameter within physical
bounds (and the kinematic rows near the robot the file embeds), the reference payload
within 10 x the rated one, frames_mm_deg agreeing with the parameters, the robot section
matching its fingerprint; each refusal names the file, the key, the value and the range.
"""

from __future__ import annotations

import pytest

from kinecal import _yaml as yaml
from kinecal.errors import ConfigError
from kinecal.io import load_model, save_model
from tests.cli_contract import failed_with, run_kinecal


@pytest.fixture(scope="module")
def doc(data):
    return yaml.load(data["model"].read_text())


def _edited(doc, tmp_path, edit):
    import copy

    d = copy.deepcopy(doc)
    edit(d)
    f = tmp_path / "edited.yaml"
    f.write_text(yaml.dump(d, sort_keys=False))
    return f


def _param(name, value):
    def edit(d):
        d["parameters"][name]["value"] = value

    return edit


BAD = [
    # (edit, needles of the message)
    (_param("joint2.theta_offset", 1e9), ["joint2.theta_offset.value", "1e+09 deg"]),
    (_param("joint2.theta_offset", -50.0), ["joint2.theta_offset", "nominal -90 deg"]),
    (_param("joint3.alpha", -130.0), ["joint3.alpha", "from the robot's nominal"]),
    (_param("joint2.a", 2330.0), ["joint2.a.value", "mm from the robot's nominal"]),
    (_param("joint2.ka1", 1e9), ["joint2.ka1.value", "transmission error", "10 deg"]),
    (_param("joint2.ka1", 45.0), ["joint2.ka1.value", "-10 to 10 deg"]),
    (
        _param("joint3.lambda", 1e9),
        ["joint3.lambda.value", "compliance", "0.1 rad of deflection"],
    ),
    # J3 of the LR Mate carries 0.42 m of lever per unit payload weight: 0.24 rad/m
    (_param("joint3.lambda", -0.5), ["joint3.lambda.value", "-0.24 to 0.24"]),
    (_param("base.r", 1e5), ["base.r.value", "two turns"]),
    (_param("base.x", 2e6), ["base.x.value", "within 1e+06 mm"]),
    (
        lambda d: d["model"].__setitem__("reference_payload_kg", 1e9),
        ["model.reference_payload_kg", "1e+09 kg", "up to 70 kg", "rated 7 kg"],
    ),
    (
        lambda d: d["model"].__setitem__("reference_payload_kg", 0),
        ["model.reference_payload_kg", "positive mass"],
    ),
    (
        lambda d: d["frames_mm_deg"]["base"].__setitem__("x", 0.0),
        ["frames_mm_deg.base.x", "the parameters give -1105", "delete the block"],
    ),
    (
        lambda d: d["frames_mm_deg"].__setitem__("cam@x", d["frames_mm_deg"]["cam"]),
        ["frames_mm_deg", "expected", "'base', 'cam'"],
    ),
    (
        lambda d: d["robot"]["joints"][1].__setitem__("a", 340.0),
        ["robot_sha256", "edited after the calibration"],
    ),
    # the model section's own fields: the key named once, after the file
    (lambda d: d["model"].__setitem__("sets", ["", ""]), ["model.sets", "unique"]),
    (lambda d: d["model"].__setitem__("markers", "a"), ["model.markers", "labels"]),
    (lambda d: d["model"].__setitem__("hayati", [9]), ["model.hayati", "1..6"]),
    (lambda d: d["model"].__setitem__("load", "yes"), ["model.load"]),
]


@pytest.mark.parametrize(("edit", "needles"), BAD)
def test_issue_35_bad_model_values_are_refused(doc, tmp_path, edit, needles):
    f = _edited(doc, tmp_path, edit)
    with pytest.raises(ConfigError) as e:
        load_model(f)
    msg = str(e.value)
    assert msg.startswith(str(f)), msg
    assert msg.count(str(f)) == 1, msg  # the file named once
    for n in needles:
        assert n in msg, msg


def test_issue_35_values_within_bounds_load(doc, tmp_path, data):
    """A realistic edit (a hand-set transmission term, no frames block, no
    fingerprint: an older file) still loads, and a written model reads back equal."""

    def edit(d):
        d["parameters"]["joint2.ka1"]["value"] = 0.02
        del d["frames_mm_deg"]
        del d["robot_sha256"]

    cal = load_model(_edited(doc, tmp_path, edit))
    assert cal.params.shape == load_model(data["model"]).params.shape
    out = save_model(tmp_path / "again.yaml", cal)
    again = load_model(out)
    assert (again.params == cal.params).all()


@pytest.mark.parametrize(
    "command",
    [
        ["compensate", "{targets}", "--model", "{model}", "--out", "{out}"],
        ["evaluate", "{test}", "--model", "{model}"],
        ["fk", "--model", "{model}", "0", "0", "0", "0", "90", "0"],
        ["export-urdf", "{model}", "--out", "{out}"],
    ],
)
def test_issue_35_commands_refuse_a_damaged_model(capsys, data, doc, tmp_path, command):
    f = _edited(doc, tmp_path, _param("joint2.theta_offset", 1e9))
    names = {**{k: str(v) for k, v in data.items()}, "model": f, "out": tmp_path / "o"}
    args = [a.format(**names) for a in command]
    res = run_kinecal(capsys, *args)
    failed_with(res, "edited.yaml", "joint2.theta_offset.value", "1e+09 deg")
    assert not (tmp_path / "o").exists()
