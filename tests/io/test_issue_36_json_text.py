"""json_text writes report.json and manifest.json in one pass (issue 36): the very text
of ``json.dumps(clean(data), indent=2)``, for every kind of value kinecal writes."""

from __future__ import annotations

import collections
import enum
import json

import numpy as np
import pytest

from kinecal.io import json_text
from kinecal.io._json import clean


class _Level(enum.IntEnum):
    HIGH = 3


DOCS = [
    {},
    [],
    {"a": [], "b": {}, "c": [[]], "d": [{}]},
    {"x": [1.0, float("nan"), 2.5, float("inf"), -0.0, 1e-300], "t": (1, 2)},
    {"arr": np.arange(4.0), "f32": np.float32(1.1), "i": np.int64(7)},
    {"yes": np.bool_(True), "no": np.bool_(False), "py": [True, False, None]},
    {1: "a", "1": "b", None: 3, 2.5: "c", (1, 2): "d"},  # keys as str(key)
    np.array(3.0),
    np.zeros((2, 3)),
    np.array([[1, 2], [3, 4]]),
    {"s": 'héllo "q" \n\t\\ ü €', "level": _Level.HIGH, "big": 2**70},
    collections.OrderedDict(b=1, a=[np.nan, np.float64(-np.inf), np.float32(2)]),
    [{"name": "joint1.a", "value": 0.1, "std": None}, [1.5, 2], (np.int32(1),)],
]


@pytest.mark.parametrize("doc", DOCS, ids=range(len(DOCS)))
def test_issue_36_json_text_is_the_standard_encoders_text(doc):
    assert json_text(doc) == json.dumps(clean(doc), indent=2) + "\n"


def test_issue_36_json_text_refuses_what_json_refuses():
    with pytest.raises(TypeError, match="complex is not JSON serializable"):
        json_text({"a": [1.0, 1j]})
