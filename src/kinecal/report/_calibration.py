"""The HTML report of one calibration, drawn from its result folder.

:func:`write_report` reads ``model.yaml``, ``report.json`` and ``residuals.csv`` (see
:mod:`._poses`) and writes ``report.html``: the report is a function of these files
alone, so ``kinecal report DIR`` redraws it, and ``kinecal calibrate`` writes it by the
same function. Figures are inline SVG (no matplotlib, no external files).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from kinecal._log import Logger
from kinecal.io._json_read import loads
from kinecal.report import _figures as F
from kinecal.report._certificate import certificate_html
from kinecal.report._format import details, e, figure, num, page_parts, ratio, table
from kinecal.report._headline import accuracy_html
from kinecal.report._poses import (
    FIGURE_POSES,
    RESIDUALS_CSV,
    PoseErrors,
    read_pose_errors,
)
from kinecal.report._tables import (
    SIGNIFICANT,
    compliance_table,
    dh_table,
    frames_table,
    parameter_table,
)

__all__ = ["render_calibration_report", "write_calibration_report", "write_report"]

log = Logger(__name__)


# ---------------------------------------------------------------------- summary parts
_MET = ("rms_mm", "std_mm", "mean_mm", "max_mm")


def _accuracy_table(summary: Mapping[str, Any]) -> str:
    """Before / after on the calibration data, and held-out (cross-validated) rows."""
    rows = []
    rot = summary["after"].get("rot_rms_deg") is not None  # pose data: orientation too

    def add(label: str, n: Any, m: Mapping[str, Any], se: Any = None) -> None:
        xyz = list(m.get("rms_xyz_mm") or [None] * 3)
        rms = num(m.get("rms_mm")) + (f" ± {num(se, 2)}" if se is not None else "")
        rows.append(
            [e(label), e(n if n is not None else "—"), rms]
            + [num(m.get(k)) for k in _MET[1:]]
            + [num(x) for x in xyz]
            + ([num(m.get("rot_rms_deg")), num(m.get("rot_max_deg"))] if rot else [])
        )

    add(
        "calibration data, before",
        summary["before"].get("n"),
        summary["before"],
    )
    add(
        "calibration data, after",
        summary["after"].get("n"),
        summary["after"],
    )
    cv = summary.get("cross_validation")
    if cv:
        k = cv.get("folds")
        for name, fig in _cv_figures(cv):
            add(
                f"held-out, {k}-fold cross-validation, {name}: nominal",
                summary["before"].get("n"),
                fig["nominal"],
                fig["nominal"].get("se_mm"),
            )
            add(
                f"held-out, {k}-fold cross-validation, {name}: this model",
                summary["before"].get("n"),
                fig["model"],
                fig["model"].get("se_mm"),
            )
    sel = summary.get("model_selection")
    if sel:
        for c in sel.get("candidates", []):
            if c.get("chosen"):
                m = {"rms_mm": c.get("cv_rms_mm")}
                add(
                    f"held-out, {sel.get('folds')}-fold CV of --model auto: {c.get('label')}",
                    summary["before"].get("n"),
                    m,
                    c.get("cv_se_mm"),
                )
    head = ["data", "poses", "RMS [mm]", "Std [mm]", "Avg [mm]", "Max [mm]"]
    head += ["RMS x [mm]", "RMS y [mm]", "RMS z [mm]"]
    head += ["orientation RMS [deg]", "orientation max [deg]"] if rot else []
    return table(head, rows)


_FOLD_WORDS = {
    "in-session": "poses drawn at random from the calibrated workspace: what new poses "
    "among the measured ones see",
    "new region": "whole regions of the workspace held out: what a new task in another "
    "part of the workspace sees",
    "new session": "whole sessions (sets) held out, their user frames refitted: what the "
    "next set-up sees",
}


def _cv_figures(cv: Mapping[str, Any]) -> list[tuple[str, Mapping[str, Any]]]:
    """The named figures of report.json's cross_validation (a file of an earlier
    release has one, at the top)."""
    figs = cv.get("figures")
    if isinstance(figs, Mapping) and figs:
        return [(str(k), v) for k, v in figs.items() if isinstance(v, Mapping)]
    return [(str(cv.get("unit") or "folds"), cv)]


def _heldout_section(summary: Mapping[str, Any]) -> list[str]:
    out = []
    cv = summary.get("cross_validation")
    for name, fig in _cv_figures(cv) if cv else []:
        nom, mod = fig["nominal"], fig["model"]
        folds = mod.get("fold_rms_mm") or []
        rows = [
            [str(i + 1), num(a), num(b), num(c)]
            for i, (a, b, c) in enumerate(
                zip(
                    nom.get("fold_rms_mm") or [None] * len(folds),
                    folds,
                    mod.get("train_rms_mm") or [None] * len(folds),
                )
            )
        ]
        out += [
            f"<h2>Cross-validation, {e(name)} ({len(folds)} folds)</h2>",
            "<p>Each fold is calibrated on the other poses and scored on its own: "
            f"{e(_FOLD_WORDS.get(name, 'folds of ' + name))}.</p>",
            table(
                [
                    "fold",
                    "nominal: held-out RMS [mm]",
                    "model: held-out RMS [mm]",
                    "model: training RMS [mm]",
                ],
                rows,
            ),
        ]
    for line in (cv or {}).get("advice") or []:
        out.append(f"<p><strong>Note.</strong> {e(line)}</p>")
    sel = summary.get("model_selection")
    if sel:
        rows, cls = [], []
        for c in sel.get("candidates", []):
            rows.append(
                [
                    e(c.get("label")),
                    e(c.get("parameters")),
                    num(c.get("prior_scale")),
                    num(c.get("cv_rms_mm")) + f" ± {num(c.get('cv_se_mm'), 2)}",
                    num(c.get("train_rms_mm")),
                    "chosen" if c.get("chosen") else "",
                ]
            )
            cls.append("sig" if c.get("chosen") else "")
        out += [
            f"<h2>Model selection (--model auto, {sel.get('folds')}-fold cross-validation)</h2>",
            f"<p>Rule: {e(sel.get('rule', ''))}; chosen: <b>{e(sel.get('chosen'))}</b>.</p>",
            table(
                [
                    "candidate",
                    "parameters",
                    "prior scale",
                    "held-out RMS ± se [mm]",
                    "training RMS [mm]",
                    "",
                ],
                rows,
                cls=cls,
            ),
        ]
        out += [f"<p class=warn>{e(w)}</p>" for w in sel.get("warnings", [])]
    return out


def _acceptance(summary: Mapping[str, Any]) -> str:
    """The --accept verdict, or nothing without limits."""
    acc = summary.get("acceptance")
    if not acc:
        return ""
    ok = bool(acc.get("pass"))
    checks = ", ".join(
        f"{e(str(c['figure']).replace('_mm', '').upper())} {num(c['value'])} mm "
        f"{'≤' if c['pass'] else '>'} {num(c['limit'])} mm"
        for c in acc.get("checks", [])
    )
    return (
        f"<p class=accept><b class={'ok' if ok else 'warn'}>"
        f"Acceptance: {'PASS' if ok else 'FAIL'}</b> — {checks}; judged on "
        f"{e(acc.get('judged'))}.</p>"
    )


def _warnings(summary: Mapping[str, Any]) -> str:
    """Every warning, with the full list of the rows or parameters it concerns (the
    message names only the first few)."""
    diagnostics = summary.get("diagnostics")
    if diagnostics is None:  # a report.json of an earlier version
        diagnostics = [
            {"message": w, "severity": "warning", "rows": [], "parameters": []}
            for w in summary.get("warnings", [])
        ]
    by_row = {
        o["row"]: o
        for o in [*summary.get("outliers", []), *summary.get("rejected_rows", [])]
    }
    items = []
    for d in diagnostics:
        if d.get("severity") != "warning":
            continue
        extra = ""
        rows, names = d.get("rows", []), d.get("parameters", [])
        if rows and all(r in by_row for r in rows):
            extra = details(
                f"all {len(rows)} rows",
                table(
                    ["row (file line)", "error [mm]", "z [-]"],
                    [
                        [str(r), num(by_row[r]["error_mm"]), ratio(by_row[r]["z"])]
                        for r in rows
                    ],
                ),
            )
        elif rows:
            extra = details(
                f"all {len(rows)} rows", f"<p>{e(', '.join(map(str, rows)))}</p>"
            )
        elif len(names) > 3:
            extra = details(f"all {len(names)}", f"<p>{e(', '.join(names))}</p>")
        items.append(f"<li class=warn>{e(d['message'])}{extra}</li>")
    return f"<ul>{''.join(items)}</ul>" if items else ""


def _identifiability(ident: Mapping[str, Any]) -> list[str]:
    out = ["<h2>Identifiability</h2><ul>"]
    out += [f"<li>{e(x)}</li>" for x in ident.get("summary", [])]
    out.append("</ul>")
    strong = ident.get("strong_correlations", [])
    if strong:
        out.append(
            details(
                f"all {len(strong)} pairs of estimated parameters with |correlation| > 0.95",
                table(
                    ["parameter", "parameter", "correlation [-]"],
                    [[e(s["a"]), e(s["b"]), num(s["correlation"])] for s in strong],
                    left=2,
                ),
            )
        )
    return out


# ---------------------------------------------------------------------- the page
def render_calibration_report(
    summary: Mapping[str, Any], cal: Any, poses: PoseErrors | None
) -> str:
    """The HTML text of a calibration report (:func:`_report_parts` joined)."""
    return "".join(_report_parts(summary, cal, poses))


def _report_parts(
    summary: Mapping[str, Any], cal: Any, poses: PoseErrors | None
) -> list[str]:
    """The HTML text of a calibration report, in pieces (:func:`page_parts`).

    Parameters
    ----------
    summary : the content of ``report.json`` (:func:`calibration_summary`).
    cal : CalibratedModel, the content of ``model.yaml``.
    poses : per-pose errors (``residuals.csv``); None: the report has no per-pose figures.
    """
    ident = summary["identifiability"]
    n_par = len(summary.get("parameters", [])) or cal.model.size
    body = _summary_box(summary, n_par)
    body.append(certificate_html(summary))
    body += _heldout_section(summary)
    body += _parameter_sections(summary, cal, n_par)
    body += _identifiability(ident)
    body += _row_table(
        summary.get("rejected_rows", []),
        "Rejected rows (gross errors, left out of the fit)",
        "row (file line)",
    )
    body += _row_table(
        summary.get("outliers", []), "Outliers (kept in the data, reported here)", "row"
    )
    body.append("<h2>Figures</h2>")
    figures = "".join("\n" + f for f in _figures(summary, poses))
    return page_parts(
        f"kinecal calibration report: {summary.get('robot')}",
        "\n".join(body),
        [figures],
    )


def _summary_box(summary: Mapping[str, Any], n_par: int) -> list[str]:
    """The report's opening box: the fit in one sentence, the accuracy, the acceptance,
    the terms not identifiable and the warnings."""
    ident = summary["identifiability"]
    data = summary.get("data", {})
    unident = ident.get("unidentifiable", [])
    dropped = "".join(
        f"<li>{e(d['name'])}"
        + (
            " ≈ "
            + " ".join(
                f"{c['coefficient']:+.3g}·{e(c['name'])}" for c in d["explained_by"]
            )
            if d.get("explained_by")
            else " does not affect the measurements"
        )
        + "</li>"
        for d in unident
    )
    conv = (
        "Converged."
        if summary.get("success")
        else "<span class=bad>Did not converge.</span>"
    )
    return [
        "<div class=box>",
        f"<p><b>{e(summary.get('robot'))}</b>, model <b>{e(summary.get('model'))}</b>: "
        f"{ident.get('estimated')} of {n_par} parameters estimated from {e(data.get('n'))} "
        f"{e(data.get('kind', ''))} poses ({e(data.get('source', ''))}). {conv} "
        f"Noise estimate {num(summary.get('noise_sigma_mm'))} mm per axis; fit "
        f"{num(summary.get('seconds'), 3)} s.</p>",
        accuracy_html(summary),
        _acceptance(summary),
        _accuracy_table(summary),
        "<p class=muted>Errors are 3-D position errors; before: nominal kinematics with "
        "fitted user and tool frames. Validate on poses not used here with "
        "<code>kinecal evaluate</code>"
        + (
            ""
            if summary.get("cross_validation")
            else " or run with <code>--cv K</code>"
        )
        + ".</p>",
        "<p>Not identifiable from these poses (held at their start values):</p>"
        f"<ul>{dropped or '<li>none</li>'}</ul>",
        _warnings(summary),
        "</div>",
    ]


def _parameter_sections(summary: Mapping[str, Any], cal: Any, n_par: int) -> list[str]:
    """The frames, joint geometry, compliance, every parameter and the stages."""
    stages = [
        [
            e(s["name"]),
            e(s["parameters"]),
            num(s["rms_before_mm"]),
            num(s["rms_after_mm"]),
            e(s["iterations"]),
            e(s["status"]),
            num(s["seconds"], 3),
        ]
        for s in summary.get("stages", [])
    ]
    head = ["stage", "parameters", "RMS before [mm]", "RMS after [mm]", "iterations"]
    return [
        "<h2>User and tool frames <small class=muted>(paper Tables 3, 6)</small></h2>",
        frames_table(cal),
        "<h2>Joint geometry (DH parameters) <small class=muted>(paper Tables 4, 7)</small></h2>",
        dh_table(cal),
        "<h2>Joint compliance and stiffness <small class=muted>(paper Tables 4, 7)</small></h2>",
        compliance_table(cal),
        "<h2>All parameters</h2>",
        "<p class=muted>Change from nominal: estimate − start value (the nominal robot; "
        "the frames: fitted to the data with nominal kinematics; transmission and "
        f"compliance terms: 0), highlighted where it exceeds {SIGNIFICANT:g} std. "
        "std / prior std near 1: the value comes from the prior, not the data.</p>",
        details(
            f"show all {n_par}",
            parameter_table(summary.get("parameters", [])),
            open_=True,
        ),
        "<h2>Stages</h2>",
        table([*head, "status", "time [s]"], stages),
    ]


def _figures(summary: Mapping[str, Any], poses: PoseErrors | None) -> list[str]:
    out = []
    if poses is not None:
        # The histogram counts every pose (one pass); the figures that draw poses one
        # by one take a sample of a large run (:meth:`PoseErrors.sample`).
        # A large residuals.csv is read as a sample, with every row's norms.
        hist_b = poses.all_before
        hist_b = np.linalg.norm(poses.before_mm, axis=1) if hist_b is None else hist_b
        hist_a = poses.all_after
        hist_a = np.linalg.norm(poses.after_mm, axis=1) if hist_a is None else hist_a
        total = poses.total or poses.n
        poses = poses.sample(FIGURE_POSES)
        if total > poses.n:
            out.append(
                f"<p class=muted>The figures per pose show {poses.n} of the {total} "
                f"poses (the {FIGURE_POSES // 100} largest errors after calibration and "
                "poses evenly spaced through the data); the histogram and the tables "
                "above count all of them.</p>"
            )
        eb = np.linalg.norm(poses.before_mm, axis=1)
        ea = np.linalg.norm(poses.after_mm, axis=1)
        out.append(
            figure(
                F.fig_errors_before_after(eb, ea, "position error per pose"),
                "Position error per pose before and after calibration [mm] (calibration data).",
            )
        )
        out.append(
            figure(
                F.fig_error_histogram(
                    {"before": hist_b, "after": hist_a},
                    "count of position errors",
                    log=True,
                    colors=F.COLORS,
                ),
                "Histogram of the position errors on the calibration data [mm].",
            )
        )
    rms = {
        "before": summary["before"].get("rms_xyz_mm"),
        "after": summary["after"].get("rms_xyz_mm"),
    }
    cv = summary.get("cross_validation")
    for name, fig in _cv_figures(cv) if cv else []:
        if fig["model"].get("rms_xyz_mm"):
            rms[f"held-out ({name})"] = fig["model"]["rms_xyz_mm"]
    rms = {k: v for k, v in rms.items() if v}
    if rms:
        out.append(
            figure(
                F.fig_axis_rms(rms),
                "RMS position error along x, y, z of the user frame [mm].",
            )
        )
    if poses is not None:
        units = [f"J{j + 1} [{u}]" for j, u in enumerate(poses.joint_units)]
        out.append(
            figure(
                F.fig_residuals_vs_joints(poses.q, poses.after_mm, units),
                "Residuals after calibration against each controller joint value.",
            )
        )
        out.append(
            figure(
                F.fig_workspace(poses.p_mm, np.linalg.norm(poses.after_mm, axis=1)),
                "Errors after calibration over the workspace [mm].",
            )
        )
    else:
        out.append(
            f"<p class=muted>No {RESIDUALS_CSV} in the result folder: no per-pose figures.</p>"
        )
    corr = summary.get("correlation")
    if corr and len(corr.get("names", [])) > 1:
        C = np.array(corr["matrix"], dtype=float)
        out.append(
            figure(
                F.fig_correlation(C, corr["names"]),
                "Correlations of the estimated parameters.",
            )
        )
    sv = summary["identifiability"].get("singular_values")
    if sv:
        out.append(
            figure(
                F.fig_singular_values(np.array(sv, float)),
                "Singular values of the scaled identification Jacobian.",
            )
        )
    return out


# ---------------------------------------------------------------------- files
def write_report(
    folder: str | Path,
    *,
    out: str | Path | None = None,
    force: bool = False,
    poses: PoseErrors | None = None,
    model: Any = None,
) -> Path:
    """Draw ``report.html`` from a calibration result folder.

    Reads ``folder/model.yaml``, ``folder/report.json`` and, when present,
    ``folder/residuals.csv``; writes ``out`` (default ``folder/report.html``).
    ``poses``: the per-pose errors whose :meth:`~PoseErrors.to_csv` is the folder's
    residuals.csv, just written, and ``model`` what ``load_model`` returns for its
    model.yaml: the same report without reading those files again (nor hashing them
    again for the check against the manifest written with them).

    Raises
    ------
    ConfigError, DataError
        A file is missing or not what ``kinecal calibrate`` writes (named in the message).
    FileExistsError
        ``out`` exists and ``force`` is False.
    """
    from kinecal.errors import DataError
    from kinecal.io import atomic_write_bytes, atomic_write_text, load_model
    from kinecal.report._summary_check import check_manifest, check_summary

    d = Path(folder)
    target = Path(out) if out is not None else d / "report.html"
    if target.exists() and not force:
        raise FileExistsError(f"{target} exists; use --force to overwrite it.")
    js = d / "report.json"
    if poses is None or model is None:  # else: files the caller has just written
        check_manifest(d)
    try:
        summary = loads(js.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise DataError(
            f"{js}: not found; is {d} a folder written by kinecal calibrate?"
        ) from None
    except json.JSONDecodeError as exc:
        raise DataError(f"{js}: not valid JSON ({exc}).") from None
    if "iso9283" in summary and "identifiability" not in summary:
        from kinecal.report._iso9283 import render_iso9283_report  # evaluate --iso9283

        title = f"ISO 9283 evaluation: {Path(str(summary.get('data', d))).name}"
        html = render_iso9283_report(summary["iso9283"], title=title)
        return atomic_write_text(target, html, force=True)
    for key in ("identifiability", "before", "after", "parameters"):
        if key not in summary:
            raise DataError(
                f"{js}: missing key {key!r}; not a report.json of kinecal calibrate."
            )
    check_summary(summary, js)
    cal = model if model is not None else load_model(d / "model.yaml")
    res = d / RESIDUALS_CSV
    if poses is not None:
        poses = poses.as_read(res, sample=FIGURE_POSES)
    elif res.is_file():
        poses = read_pose_errors(res, sample=FIGURE_POSES)
    parts = _report_parts(summary, cal, poses)
    return atomic_write_bytes(target, [p.encode("utf-8") for p in parts], force=True)


def write_calibration_report(
    path: str | Path, result: Any, meas: Any, summary: Mapping[str, Any]
) -> Path:
    """``report.html`` of a calibration from the objects in memory (the same page as
    :func:`write_report` draws from the files ``kinecal calibrate`` writes)."""
    from kinecal.io import atomic_write_text
    from kinecal.report._poses import pose_errors

    clean = json.loads(json.dumps(summary, default=_jsonable))
    html = render_calibration_report(
        clean, result.calibrated, pose_errors(result, meas)
    )
    return atomic_write_text(path, html, force=True)


def _jsonable(x: object) -> object:
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, np.generic):
        return x.item()
    raise TypeError(f"not JSON serialisable: {type(x).__name__}")


def _row_table(rows: list[dict[str, Any]], title: str, row_label: str) -> list[str]:
    """A section listing rows with their error and z (open when 20 or fewer); none for
    no rows."""
    if not rows:
        return []
    cells = [[str(o["row"]), num(o["error_mm"]), ratio(o["z"])] for o in rows]
    return [
        f"<h2>{title}</h2>",
        details(
            f"all {len(rows)} rows",
            table([row_label, "error [mm]", "z [-]"], cells),
            open_=len(rows) <= 20,
        ),
    ]
