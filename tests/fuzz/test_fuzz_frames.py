"""Issue 34/35: the controller's frame and register files ``compensate --frames`` reads
(FANUC SYSFRAME.VA and POSREG.VA, a frames YAML) are untrusted input: damaged lines,
numbers replaced by what a hand-edited or broken file holds, the file cut short. Every
run keeps the command-line contract (exit 0 or a documented code with one ``Error:``
line, no traceback) and writes its outputs only on success."""

from __future__ import annotations

import re
import tempfile
from pathlib import Path

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from kinecal.io import load_model
from tests.cli_contract import check_contract, leftovers, run_kinecal
from tests.compensation.test_issue_34_cartesian import (
    T_TOOL,
    T_UF,
    _numbers,
    _targets,
    _taught,
)
from tests.compensation.test_issue_34_registers import _sysframe
from tests.fuzz.strategies import FUZZ, ODD_CELLS, mutated_text

# Half the suite's examples each (two targets of a kind; KINECAL_FUZZ_EXAMPLES scales
# them as the others).
HALF = settings(FUZZ, max_examples=max(FUZZ.max_examples // 2, 1))
NUMBER = re.compile(r"-?\d*\.\d+|-?\d+")


def _files(model: Path) -> dict[str, str]:
    """A program moving to P[1] and PR[1..3] in UF 1 / UT 1, and the controller files
    that give those frames and registers."""
    cal = load_model(model)
    q = _taught(np.random.default_rng(7), 4)
    T = _targets(cal, q)
    regs = [
        "[*POSREG*]$POSREG  Storage: SHADOW  Access: RW  : ARRAY[1,100] OF Position Reg"
    ]
    for i in range(3):
        x, y, z, w, p, r = (f"{v:9.3f}" for v in _numbers("fanuc-ls", T[i + 1]))
        regs += [
            f"    [1,{i + 1}] =   'R{i}' ",
            "  Group: 1   Config: N U T, 0, 0, 0",
            f"  X: {x}   Y: {y}   Z: {z}",
            f"  W: {w}   P: {p}   R: {r}",
        ]  # fmt: skip
    row = lambda M: ", ".join(f"{v:.4f}" for v in _numbers("fanuc-ls", M))  # noqa: E731
    x, y, z, w, p, r = (f"{v:.3f}" for v in _numbers("fanuc-ls", T[0]))
    prog = [
        "/PROG  FZ", "/ATTR", "/MN",
        "   1:  UFRAME_NUM=1 ;", "   2:  UTOOL_NUM=1 ;",
        "   3:J P[1] 100% FINE ;", "   4:L PR[1] 100mm/sec FINE ;",
        "   5:L PR[2] 100mm/sec CNT50 ;", "   6:J PR[3] 100% FINE ;",
        "/POS", "P[1]{", "   GP1:",
        "\tUF : 1, UT : 1,\t\tCONFIG : 'N U T, 0, 0, 0',",
        f"\tX = {x} mm,\tY = {y} mm,\tZ = {z} mm,",
        f"\tW = {w} deg,\tP = {p} deg,\tR = {r} deg", "};", "/END",
    ]  # fmt: skip
    return {
        "prog.ls": "\n".join(prog) + "\n",
        "SYSFRAME.VA": _sysframe(),
        "POSREG.VA": "\r\n".join([*regs, ""]),
        "frames.yaml": f"uframe:\n  1: [{row(T_UF)}]\nutool:\n  1: [{row(T_TOOL)}]\n",
    }


@st.composite
def _damaged(draw: st.DrawFn, text: str) -> str:
    """Line damage, or one number replaced by an odd value."""
    if draw(st.booleans()):
        return draw(mutated_text(text))
    spans = [m.span() for m in NUMBER.finditer(text)]
    a, b = spans[draw(st.integers(0, len(spans) - 1))]
    return text[:a] + draw(st.sampled_from(ODD_CELLS)) + text[b:]


def test_fuzz_controller_frame_files(point_data, capsys, tmp_path):
    files = _files(point_data["model"])
    # The undamaged files work: every target corrected through them.
    d = tmp_path / "ok"
    d.mkdir()
    for name, text in files.items():
        (d / name).write_text(text)
    frames = [a for f in ("SYSFRAME.VA", "POSREG.VA") for a in ("--frames", d / f)]
    res = run_kinecal(
        capsys, "compensate", d / "prog.ls", "--model", point_data["model"],
        "--out", d / "out.ls", *frames, "--allow-unreachable",
    )  # fmt: skip
    check_contract(res)
    assert res.code == 0 and (d / "OUT_PR.ls").exists(), str(res)
    assert "4 Cartesian targets: 4 corrected" in res.err, str(res)

    @HALF
    @given(
        victim=st.sampled_from(["SYSFRAME.VA", "POSREG.VA", "frames.yaml"]),
        data=st.data(),
    )
    def check(victim: str, data: st.DataObject) -> None:
        d = Path(tempfile.mkdtemp(dir=tmp_path))
        for name, text in files.items():
            (d / name).write_text(text)
        (d / victim).write_text(data.draw(_damaged(files[victim])))
        use = (
            ["frames.yaml"] if victim == "frames.yaml" else ["SYSFRAME.VA", "POSREG.VA"]
        )
        res = run_kinecal(
            capsys, "compensate", d / "prog.ls", "--model", point_data["model"],
            "--out", d / "out.ls", *(a for f in use for a in ("--frames", d / f)),
            "--allow-unreachable",
        )  # fmt: skip
        check_contract(res)
        assert (d / "out.ls").exists() == (res.code == 0), str(res)
        assert not leftovers(d)

    check()


def test_fuzz_cartesian_programs(point_data, capsys, tmp_path):
    """Programs with Cartesian targets in the four formats (FANUC P[] with UF/UT and
    CONFIG, KRL E6POS, RAPID robtargets with tooldata/wobjdata, URScript poses),
    damaged line by line or number by number."""
    from tests.compensation.test_issue_34_cartesian import FRAME_ARGS, WRITERS

    cal = load_model(point_data["model"])
    q = _taught(np.random.default_rng(11), 3)
    texts = {}
    for fmt, (writer, ext) in WRITERS.items():
        T_uf = np.eye(4) if fmt == "urscript" else T_UF
        texts[fmt] = (writer(cal, q, _targets(cal, q, T_uf=T_uf)), ext)

    @HALF
    @given(fmt=st.sampled_from(sorted(texts)), data=st.data())
    def check(fmt: str, data: st.DataObject) -> None:
        text, ext = texts[fmt]
        d = Path(tempfile.mkdtemp(dir=tmp_path))
        src = d / f"prog{ext}"
        src.write_text(data.draw(_damaged(text)))
        out = d / f"out{ext}"
        res = run_kinecal(
            capsys, "compensate", src, "--model", point_data["model"], "--out", out,
            *FRAME_ARGS[fmt](), "--allow-unreachable",
        )  # fmt: skip
        check_contract(res)
        assert out.exists() == (res.code == 0), str(res)
        assert not leftovers(d)

    check()
