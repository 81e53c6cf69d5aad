"""kinecal benchmarks: ``python -m benchmarks [--out FILE] [--quick]`` (``make bench``).

Each case runs several times; the median wall time is reported with the machine it ran
on, in a JSON file and a short table. Baselines run in the same process on the same data:
scipy's ``least_squares`` with finite-difference Jacobians and the paper's fixed-step
update (zeta = 0.005). Not part of ``make test``. The cases: benchmarks/_sections.py.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

from benchmarks import _sections as sec
from benchmarks._common import _machine


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="python -m benchmarks")
    ap.add_argument("--out", default="benchmarks/results.json")
    ap.add_argument("--quick", action="store_true", help="fewer repeats")
    ap.add_argument("--planning", action="store_true", help="the pose planning study")
    ap.add_argument("--figures", help="with --planning: write its figures here")
    ap.add_argument(
        "--robust", action="store_true", help="the breakdown study of the rejection"
    )
    ap.add_argument(
        "--stripes", action="store_true", help="only the stripe benchmarks (issue 24)"
    )
    ap.add_argument(
        "--issue26",
        action="store_true",
        help="only the issue-26 rows (large data, --model auto, start-up), merged into "
        "--out",
    )
    ap.add_argument(
        "--issue36",
        action="store_true",
        help="only the issue-36 rows (the command against one-thread scipy on two data "
        "sets, passes, per-pass floor, BLAS threads, imports); --out default "
        "benchmarks/issue36.json",
    )
    ap.add_argument(
        "--large",
        action="store_true",
        help="with --issue36: only the row of 1e6 poses from CSV (minutes), merged in",
    )
    ap.add_argument(
        "--sensor",
        action="store_true",
        help="with --issue36: only the rows of sensor reconstruct (a 120-image scan), "
        "merged in",
    )
    ap.add_argument(
        "--issue38",
        action="store_true",
        help="only the issue-38 row (the default calibrate against --cv off), merged "
        "into --out",
    )
    return ap


def main(argv: list[str] | None = None) -> int:
    ap = _parser()
    args = ap.parse_args(argv)
    if args.issue36:
        from benchmarks._issue36 import main as issue36

        out = (
            "benchmarks/issue36.json" if args.out == ap.get_default("out") else args.out
        )
        return issue36(out, args.quick, args.large, args.sensor)
    if args.stripes:
        from benchmarks._stripes import main as stripes_main

        out_args = [] if args.out == ap.get_default("out") else ["--out", args.out]
        return stripes_main(out_args + (["--quick"] if args.quick else []))
    if args.issue26:
        from benchmarks._large import issue26

        return issue26(args.out)
    if args.robust:
        from benchmarks._robust import main as robust

        if args.out == ap.get_default("out"):
            args.out = "benchmarks/robust.json"
        return robust(args)
    if args.planning:
        from benchmarks._planning import main as planning

        if args.out == ap.get_default("out"):  # not the main benchmarks' file
            args.out = "benchmarks/planning.json"
        return planning(args)
    if args.issue38:
        b = sec.Bench(3 if args.quick else 7, 0)
        sec.default_cv_case(b)
        return _merge(args.out, b.results)
    rep = 3 if args.quick else 7
    # Model evaluations take milliseconds: many more repeats steady their median on a
    # shared VM (its speed drifts by 20-30 % within minutes).
    b = sec.Bench(rep, 10 * rep)
    print("kinecal benchmarks", json.dumps(_machine()), flush=True)
    from kinecal.simulation import LaserTracker, experiment2

    e = experiment2(3, tracker=LaserTracker(5e-6, 0.0))
    cal, code = sec.kernel_cases(b, e)
    sec.calibration_cases(b, e, code)
    fit = sec.scipy_cases(b, e)
    sec.process_cases(b, e, fit)
    sec.default_cv_case(b)
    sec.fixed_step_case(b, fit)
    sec.auto_cases(b, e, fit)
    rng = sec.compensation_cases(b, e, cal)
    sec.sensor_cases(b, rng, args.quick)
    sec.file_and_startup_cases(b)
    # 9. stripe extraction: accuracy per method, a whole scan on one core (issue 24)
    from benchmarks._stripes import stripe_benchmarks

    stripes = stripe_benchmarks(args.quick)
    out = {
        "machine": _machine(),
        "results": b.results,
        "stripes": stripes,
        "created_unix": time.time(),
        "repeats": rep,
    }
    _write(args.out, out)
    return 0


def _write(path: str, out: dict[str, Any]) -> None:
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(path).with_suffix(".tmp")
    tmp.write_text(json.dumps(out, indent=2) + "\n")
    os.replace(tmp, path)
    print(f"-> {path}")


def _merge(path: str, rows: dict[str, dict[str, Any]]) -> int:
    """Rows merged into the results file at ``path`` (kept: every other row)."""
    p = Path(path)
    out = json.loads(p.read_text()) if p.exists() else {"machine": _machine()}
    out.setdefault("results", {}).update(rows)
    out["issue38_created_unix"] = time.time()
    _write(path, out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
