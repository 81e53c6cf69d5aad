"""model.yaml is written without PyYAML where it can be (issue 36): the very text
PyYAML writes, for every kind of value a model document holds; anything else is left
to PyYAML (dump returns None), and the document reads back as itself."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from kinecal import _yaml
from kinecal.io._yaml_plain import dump

WORDS = ["J1", "joint1.theta_offset", "base@tracker", "/tmp/a_b/c-1.csv", "_x", "mm"]
WORDS += ["0.1.0", "7cc1ae203df4a43e", "12e5x", "deg", "estimated", "", "a" * 100]
QUOTED = ["yes", "Off", "NULL", "1234", "0x1f", "0b101", "1.5", ".inf"]
QUOTED += ["a: b", "#x", "x\ny", "2024-01-01", "1:20", "~", "'q'", "@x", "a "]
# numbers in exponent notation as kinecal reads YAML (1.2), strings in YAML 1.1
QUOTED += ["12e5", "1e-5", "2E5"]
# written plain by PyYAML, but beyond the simple rules of dump: left to PyYAML too
BEYOND = ["é", "a" * 101, "0b1a", "-5", "a b"]


def _pyyaml(doc):
    return _yaml.dump(doc, sort_keys=False, allow_unicode=True, width=100)


def _random_doc(rng, depth=0):
    def value(d):
        kind = rng.integers(0, 9 if d < 3 else 6)
        if kind == 0:
            return WORDS[rng.integers(len(WORDS))]
        if kind == 1:
            return float(rng.choice([0.0, -0.0, 1e16, 1e-5, np.inf, -np.inf, np.nan]))
        if kind == 2:
            return float(rng.normal() * 10.0 ** rng.integers(-12, 12))
        if kind == 3:
            return int(rng.integers(-(10**6), 10**6))
        if kind == 4:
            return bool(rng.integers(2))
        if kind == 5:
            return None
        if kind in (6, 7):
            return [value(d + 1) for _ in range(rng.integers(0, 4))]
        return {
            WORDS[rng.integers(6)] + str(i): value(d + 1)
            for i in range(rng.integers(0, 4))
        }

    return {f"k{i}": value(depth) for i in range(1 + rng.integers(0, 6))}


@pytest.mark.parametrize("seed", range(40))
def test_issue_36_yaml_text_is_pyyamls(seed):
    doc = _random_doc(np.random.default_rng(seed))
    text = dump(doc)
    assert text == _pyyaml(doc)
    back = _yaml.load(text)
    assert repr(back) == repr(doc)  # the same document (nan == nan in repr)


@pytest.mark.parametrize("word", QUOTED + BEYOND)
def test_issue_36_what_yaml_would_quote_is_left_to_pyyaml(word):
    assert dump({"a": [word]}) is None
    assert dump({word: 1}) is None
    if word in QUOTED:
        assert _pyyaml({"a": word}) != f"a: {word}\n"  # PyYAML does quote it


@pytest.mark.parametrize("odd", [(1, 2), np.float64(1.0), 1j, {1: 2}, b"x"])
def test_issue_36_other_types_are_left_to_pyyaml(odd):
    assert dump({"a": odd}) is None


def test_issue_36_a_model_file_is_written_without_pyyaml_and_read_as_saved(tmp_path):
    from kinecal.io import load_model, save_model
    from kinecal.io._model_file import save_model_as_read

    spaced = load_model(_model_file(tmp_path))  # source 'experiment 2 (simulated)'
    assert save_model_as_read(tmp_path / "s.yaml", spaced)[1] is None  # by PyYAML
    cal = replace(spaced, info={**spaced.info, "source": "/data/train.csv"})
    path, model = save_model_as_read(tmp_path / "m.yaml", cal)
    assert model is not None
    again = load_model(path)
    assert path.read_text() == save_model(tmp_path / "n.yaml", again).read_text()
    for name in ("params", "std"):
        assert np.array_equal(
            getattr(model, name), getattr(again, name), equal_nan=True
        )
    assert model.status == again.status and model.info == again.info
    assert model.model.spec == again.model.spec


def _model_file(tmp_path):
    from kinecal.identification import calibrate
    from kinecal.io import save_model
    from kinecal.models import ModelSpec
    from kinecal.simulation import LaserTracker, experiment2

    exp = experiment2(3, tracker=LaserTracker(5e-6, 0.0), n_side=4)
    res = calibrate(exp.truth.robot, exp.train, ModelSpec(name="kinematic"))
    return save_model(tmp_path / "first.yaml", res.calibrated)
