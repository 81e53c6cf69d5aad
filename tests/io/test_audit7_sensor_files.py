"""Audit 7: a sensor YAML whose ``format`` is ``true`` read as format 1 (``True == 1``
in Python), as a model file's ``kinecal_model: true`` did."""

from __future__ import annotations

import pytest

from kinecal.errors import ConfigError
from kinecal.io import load_sensor, save_sensor
from kinecal.sensor import paper_sensor


@pytest.mark.parametrize("value", ["true", "1.0", "'1'"])
def test_a_retyped_format_is_refused(tmp_path, value):
    f = tmp_path / "sensor.yaml"
    save_sensor(f, paper_sensor(), {})
    text = f.read_text()
    assert "format: 1\n" in text
    f.write_text(text.replace("format: 1\n", f"format: {value}\n", 1))
    with pytest.raises(ConfigError, match=r"sensor\.yaml: format: expected 1"):
        load_sensor(f)


def test_the_written_format_reads(tmp_path):
    f = tmp_path / "sensor.yaml"
    save_sensor(f, paper_sensor(), {})
    assert load_sensor(f) is not None
