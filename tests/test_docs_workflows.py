"""docs/workflows.md runs: its ``python`` blocks in order as one script, in a fresh
folder (the program it compensates copied from tests/data)."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "workflows.md"


def test_workflows_page_runs(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    shutil.copy(ROOT / "tests/data/programs/pick_demo.ls", tmp_path / "pick_demo.ls")
    blocks = re.findall(r"```python\n(.*?)```", PAGE.read_text("utf-8"), flags=re.S)
    assert len(blocks) >= 7
    scope: dict[str, object] = {}
    for block in blocks:
        exec(compile(block, str(PAGE), "exec"), scope)
    out = capsys.readouterr().out
    assert "kinematic: held out" in out and "nominal" in out
