"""Fuzz (audit 9): one joint value of a robot program (FANUC, URScript, RAPID, KRL)
replaced by a token that is no plain number (a word, a decimal comma, an expression,
an overflow, nothing). The run refuses the program (exit 2) or names the target's line;
it never writes the program back with that target silently uncorrected or misread (a
KRL ``A1 15,5`` was read as 15; ``movej([d2r(10), ...])`` was skipped without a word)."""

from __future__ import annotations

import tempfile
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from tests.cli_contract import check_contract, run_kinecal
from tests.fuzz.strategies import FUZZ

DATA = Path(__file__).parents[1] / "data" / "programs"
NAMES = ("pick_demo.ls", "pick_demo.script", "pick_demo.mod", "pick_demo.dat")
BAD = ("abc", "1,5", "", "d2r(10)", "10+5", "1e999", "--5", "5..0", "0x10", "1 2")


@pytest.mark.slow  # 25 runs of compensate: 0.6 s
def test_fuzz_a_damaged_joint_value_is_refused_or_named(point_data, capsys, tmp_path):
    from kinecal.io import read_program

    spans = {n: [(pt.line, s) for pt in read_program(DATA / n).points
                 for s in pt.spans] for n in NAMES}  # fmt: skip

    @FUZZ
    @given(
        name=st.sampled_from(NAMES), k=st.integers(0, 1000), bad=st.sampled_from(BAD)
    )
    def check(name: str, k: int, bad: str) -> None:
        text = (DATA / name).read_bytes().decode("utf-8")  # (CR LF kept: the spans)
        line, (a, b) = spans[name][k % len(spans[name])]
        d = Path(tempfile.mkdtemp(dir=tmp_path))
        prog, out = d / name, d / f"out{Path(name).suffix}"
        new = text[:a] + (" " if text[a].isspace() else "") + bad + text[b:]
        prog.write_bytes(new.encode("utf-8"))
        res = run_kinecal(
            capsys, "compensate", prog, "--model", point_data["model"], "--out", out,
            "--allow-unreachable",
        )  # fmt: skip
        check_contract(res)
        if res.code == 0:
            assert f"line {line} " in res.err or f"line {line}:" in res.err, (
                bad,
                prog.read_text(),
                str(res),
            )
        else:
            assert res.code == 2 and not out.exists(), str(res)

    check()
