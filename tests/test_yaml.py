"""kinecal._yaml: the safe loader refuses duplicate keys (issue 21)."""

from __future__ import annotations

import pytest

from kinecal import _yaml as yaml


@pytest.mark.parametrize(
    ("text", "line", "first"),
    [
        ("a: 330\na: 3300\n", 2, 1),
        ("j:\n  - {a: 1, d: 0}\n  - {a: 2, d: 0,\n     a: 3}\n", 4, 3),
        ("x:\n  y: 1\n  z: 2\n  y: 3\n", 4, 2),
        ("1: a\n1.0: b\n", 2, 1),  # equal keys of two spellings
    ],
)
def test_duplicate_keys_are_refused_with_their_lines(text, line, first):
    with pytest.raises(
        yaml.DuplicateKeyError, match=f"line {line}: duplicate key"
    ) as e:
        yaml.load(text)
    assert f"first on line {first}" in str(e.value)
    assert isinstance(e.value, yaml.YAMLError)  # readers turn it into their message


def test_valid_documents_load_as_before():
    text = "a: &x {b: 1, c: [1, 2]}\nd: *x\ne: {<<: *x, c: 3}\n"
    assert yaml.load(text) == {
        "a": {"b": 1, "c": [1, 2]},
        "d": {"b": 1, "c": [1, 2]},
        "e": {"b": 1, "c": 3},
    }
    doc = {"k": [1, {"m": None}], "s": "t"}
    assert yaml.load(yaml.dump(doc)) == doc
