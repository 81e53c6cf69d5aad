"""A long program is compensated in time linear in its targets: the per-target columns
of ``--report`` were formed from every row's joint change once per row (20 000 URScript
moves took 36 s, 32 s of it there)."""

from __future__ import annotations

import time

import pytest

MOVE = "  movej([0.174533, -1.396263, 1.570796, -1.745329, -1.570796, 0.0], a=1, v=1)\n"


@pytest.mark.slow
def test_a_long_program_is_compensated_in_linear_time(model_file, run_cli, tmp_path):
    def took(n: int) -> float:
        src = tmp_path / f"many{n}.script"
        src.write_text("def p():\n" + MOVE * n + "end\n")
        best = float("inf")
        for k in range(2):
            out = tmp_path / f"out{n}_{k}"
            t0 = time.perf_counter()
            res = run_cli(
                "compensate", str(src), "--model", str(model_file),
                "--out", str(out / "p.script"), "--report", str(out / "r.csv"),
            )  # fmt: skip
            best = min(best, time.perf_counter() - t0)
            assert res.returncode == 0, res.stderr
            assert f"{n} of {n} targets compensated" in res.stdout + res.stderr
        return best

    # 4x the targets: 4x the time, with the fixed costs less (quadratic: up to 16x).
    ratio = took(16000) / took(4000)
    assert ratio < 6.5, ratio
