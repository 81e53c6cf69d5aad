"""Issue 19: one serialisation of the parameters for model.yaml, report.json and the
HTML report."""

from __future__ import annotations

import json
import re

import pytest
import yaml


def test_issue_19_model_yaml_report_json_and_html_agree(calibrated_exp1):
    _, out = calibrated_exp1  # simulate --experiment 1, calibrate with --targets
    model = yaml.safe_load((out / "model.yaml").read_text())["parameters"]
    report = {
        p["name"]: p
        for p in json.loads((out / "report.json").read_text())["parameters"]
    }
    assert list(model) == list(report)
    for name, p in model.items():
        r = report[name]
        for key in ("value", "std", "unit", "status"):
            assert p[key] == r[key], (name, key)
        assert r["group"] and "joint" in r and "field" in r and "label" in r
    html = (out / "report.html").read_text()
    # the compliance table shows every compliance parameter in its file unit
    for name in ("joint2.lambda", "joint1.ka1"):
        p = model[name]
        row = re.search(rf"<td[^>]*>{re.escape(name)}</td>(.*?)</tr>", html)
        assert row, name
        assert p["unit"] in row.group(1)
    ntm = model["joint1.ka1"]
    assert ntm["unit"] == "deg"
    assert pytest.approx(ntm["value"], abs=1e-12) == report["joint1.ka1"]["value"]
