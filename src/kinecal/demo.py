"""The built-in demo: both of the paper's experiments on the digital twin, end to end.

For each experiment: simulate the LR Mate 200iD with the paper's identified errors (Tables
3-4, 6-7) plus effects no model captures (third and fourth harmonics on J1-J3, wrist
transmission errors, off-axis link masses), measure with a realistic instrument, calibrate
the four models of Table 5 on 100 poses, score them on the held-out poses, and check the
full model's parameters against the hidden truth.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from kinecal.identification import compare_models
from kinecal.io import (
    atomic_write_text,
    prepare_output_dir,
    save_model,
    write_json,
    write_measurements,
    write_targets,
)
from kinecal.report import comparison_table, format_table, write_comparison_report
from kinecal.simulation import (
    Experiment,
    LaserTracker,
    experiment1,
    experiment2,
    joint_ranges_deg,
    parameter_recovery,
)

__all__ = [
    "DEMO_EXTRAS",
    "DEMO_FILES",
    "DemoRun",
    "paper_demo",
    "run_demo",
    "truth_model",
]

DEMO_EXTRAS = ("harmonics", "wrist", "masses")
# What a demo folder holds (what --force replaces).
DEMO_FILES = ("experiment1", "experiment2", "summary.json", "summary.txt")
_KEY_PARAMETERS = (
    "joint2.theta_offset",
    "joint3.a",
    "joint4.theta_offset",
    "joint5.alpha",
    "joint2.lambda",
    "joint5.lambda",
    "link.s2",
)


def _recovery_html(rec: Any, to_file: dict[str, float], units: dict[str, str]) -> str:
    from kinecal.report._format import num, pm

    rows = []
    for n, e, s, q, t in zip(
        rec.names, rec.estimate, rec.std, rec.equivalent, rec.raw_truth
    ):
        if n not in _KEY_PARAMETERS:
            continue
        f = to_file[n]
        rows.append(
            f"<tr><td class=l>{n}</td><td>{pm(e * f, s * f)}</td><td>{num(q * f, 6)}</td>"
            f"<td>{num(t * f, 6)}</td><td>{(e - q) / s:+.1f}</td><td class=l>{units[n]}</td></tr>"
        )
    return (
        "<h2>Parameter recovery (full model vs hidden truth)</h2>"
        f"<p>{rec.fraction_within(3.0):.0%} of the {len(rec.names)} estimated parameters "
        "lie within 3 reported standard deviations of the equivalent truth "
        f"(max |z| {rec.max_abs_z:.2f}); "
        f"the fitted model reproduces the noise-free truth to {rec.fit_rms_mm * 1e3:.2f} um RMS "
        "(the rest are effects outside the model).</p>"
        "<table><tr><th class=l>parameter</th><th>estimate ± std</th><th>equivalent truth</th>"
        "<th>raw truth</th><th>z</th><th class=l>unit</th></tr>"
        + "".join(rows)
        + "</table>"
    )


def truth_model(exp: Any) -> Any:
    """The true robot of a simulated experiment as a model file's contents (a
    :class:`CalibratedModel` with no standard deviations, every parameter 'fixed')."""
    from kinecal.measurement import CalibratedModel

    tm, x = exp.truth.model, exp.truth.params
    if exp.train.kind == "point" and tm.spec.cam_rotation:
        # Tracker points do not see the reflector's orientation: the truth as the
        # model of point data (what calibrate writes, and plan --add reads).
        tm, x = _without_cam_rotation(tm, x)
    return CalibratedModel(
        tm,
        x,
        np.full(tm.size, np.nan),
        ["fixed"] * tm.size,
        # The payload the data were simulated at is the unit of its compliance (as a
        # calibration's reference payload): evaluate and compensate scale by it.
        exp.train.reference_payload(),
        info={
            # the kind of data the truth generated: evaluate and plan --add read it
            "kind": exp.train.kind,
            "truth": exp.truth.description,
            "extras": list(exp.truth.extras),
            "thermal_ppm_per_pose": exp.truth.thermal_ppm_per_pose,
            "outlier_poses": int(exp.outlier_rows.size),
        },
    )


def _without_cam_rotation(tm: Any, x: np.ndarray) -> tuple[Any, np.ndarray]:
    """The model ``tm`` without the cam frame's rotation, with the values of ``x`` by
    name (the rotation does not move a point at the cam frame's origin)."""
    from dataclasses import replace

    from kinecal.models import CalibrationModel

    m = CalibrationModel(tm.robot, replace(tm.spec, cam_rotation=False))
    m = m.with_references(tm.R_ref_base, None)
    index = {n: i for i, n in enumerate(tm.layout.names)}
    return m, np.array([x[index[n]] for n in m.layout.names])


@dataclass(frozen=True)
class DemoRun:
    """What :func:`paper_demo` did.

    Attributes
    ----------
    text : the summary ``kinecal demo`` prints (also in ``summary.txt``).
    summary : the figures of ``summary.json`` (per experiment the comparison table,
        joint ranges and parameter recovery).
    folder : where the results are.
    """

    text: str
    summary: dict[str, Any] = field(repr=False)
    folder: Path


def run_demo(
    out: Path,
    *,
    seed: int = 0,
    force: bool = False,
    progress: Callable[[str, str], None] | None = None,
) -> str:
    """Run the demo, write everything to ``out`` and return the printed summary
    (:func:`paper_demo`'s ``text``)."""
    return paper_demo(out, seed=seed, force=force, progress=progress).text


def _simulate(number: int, seed: int, d: Path) -> Experiment:
    """Simulate the paper's experiment ``number`` and write its data and truth to
    the directory ``d`` (made here)."""
    if number == 2:
        exp = experiment2(seed, extras=DEMO_EXTRAS, tracker=LaserTracker(5e-6, 2e-6))
    else:
        exp = experiment1(seed, extras=DEMO_EXTRAS)
    d.mkdir(exist_ok=True)
    robot = exp.truth.robot
    write_measurements(d / "train.csv", exp.train, robot, force=True)
    write_measurements(d / "test.csv", exp.test, robot, force=True)
    if exp.targets is not None:
        write_targets(d / "targets.csv", *exp.targets, force=True)
    save_model(d / "truth.yaml", truth_model(exp), force=True)
    return exp


def paper_demo(
    out: Path,
    *,
    seed: int = 0,
    force: bool = False,
    progress: Callable[[str, str], None] | None = None,
) -> DemoRun:
    """Run the demo (``kinecal demo``): both of the paper's experiments on the digital
    twin, written to ``out``.

    Per experiment, ``out/experiment{1,2}/`` gets train.csv, test.csv (and targets.csv),
    truth.yaml (the hidden true robot), model-{kinematic,ntm,rfcm,full}.yaml,
    comparison.json, report.html and figures/; ``out`` gets summary.txt and summary.json.
    """
    say: Callable[[str, str], None] = progress or (lambda stage, detail: None)
    shown = Path(out)  # where the results end up (``out`` may be staged elsewhere)
    out = prepare_output_dir(out, list(DEMO_FILES), force=force)
    t0 = time.perf_counter()
    text: list[str] = [
        "kinecal demo: the paper's two experiments on the digital twin (LR Mate 200iD)",
        f"truth: Tables 3-4 / 6-7 values + unmodelled {', '.join(DEMO_EXTRAS)}; seed {seed}",
        "",
    ]
    summary: dict[str, Any] = {
        "seed": seed,
        "extras": list(DEMO_EXTRAS),
        "experiments": {},
    }
    for number in (2, 1):
        say(f"experiment {number}", "simulating")
        d = out / f"experiment{number}"
        exp = _simulate(number, seed, d)
        robot = exp.truth.robot
        say(f"experiment {number}", "calibrating kinematic, ntm, rfcm, full")
        rows = compare_models(robot, exp.train, exp.test, progress=say)
        table = comparison_table(rows)
        full = rows[-1]
        assert full.calibrated is not None
        say(f"experiment {number}", "checking parameters against the truth")
        assert full.result is not None
        rec = parameter_recovery(full.result, exp.truth, exp.train)  # type: ignore[arg-type]
        L = full.calibrated.model.layout
        to_file = dict(zip(L.names, L.to_file))
        units = dict(zip(L.names, L.file_units))
        ranges = joint_ranges_deg(np.concatenate([exp.train.q_ctrl, exp.test.q_ctrl]))
        for r in rows:
            if r.calibrated is not None and r.model != "nominal":
                save_model(d / f"model-{r.model}.yaml", r.calibrated, force=True)
        write_json(d / "comparison.json", table, force=True)
        title = exp.name
        notes = [
            f"{exp.train.n} poses to calibrate, {exp.test.n} to test; per-joint ranges "
            + ", ".join(f"J{j + 1} {v:.0f}°" for j, v in enumerate(ranges))
            + ".",
            f"Truth: {exp.truth.description}.",
        ]
        write_comparison_report(
            d / "report.html",
            rows,
            exp.test,
            title=title,
            notes=notes,
            extra_html=_recovery_html(rec, to_file, units),
            figure_dir=d / "figures",
        )
        text.append(
            format_table(table, title=f"{title} ({exp.train.n} poses to calibrate)")
        )
        text.append(
            "joint ranges [deg]: "
            + "  ".join(f"J{j + 1} {v:.0f}" for j, v in enumerate(ranges))
        )
        text.append(
            f"parameter recovery (full): {rec.fraction_within(3.0):.0%} of {len(rec.names)} "
            f"estimated parameters within 3 std of the truth (max |z| {rec.max_abs_z:.2f})"
        )
        text.append(f"report: {shown / d.name / 'report.html'}")
        text.append("")
        summary["experiments"][str(number)] = {
            "table": table,
            "joint_ranges_deg": ranges.tolist(),
            "recovery": {
                "within_3_std": rec.fraction_within(3.0),
                "max_abs_z": rec.max_abs_z,
                "n": len(rec.names),
                "fit_rms_mm": rec.fit_rms_mm,
            },
        }
    seconds = time.perf_counter() - t0
    text.append(
        f"done in {seconds:.1f} s; results in {shown}: summary.txt, summary.json and "
        "per experiment train.csv, test.csv, truth.yaml, model-*.yaml, comparison.json, "
        "report.html, figures/ (experiment1 also targets.csv)"
    )
    summary["seconds"] = seconds
    write_json(out / "summary.json", summary, force=True)
    atomic_write_text(out / "summary.txt", "\n".join(text) + "\n", force=True)
    return DemoRun("\n".join(text), summary, shown)
