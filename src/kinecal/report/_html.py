"""Self-contained HTML reports (figures embedded as PNG data URIs, readable offline)."""

from __future__ import annotations

import base64
import html
import logging
import time
from pathlib import Path
from typing import Any

import numpy as np

from kinecal._version import __version__
from kinecal.identification import (
    CalibratedModel,
    CalibrationResult,
    ComparisonRow,
    Measurements,
    residuals,
)
from kinecal.report import _figures as F
from kinecal.typing import Float

__all__ = ["write_calibration_report", "write_comparison_report"]

log = logging.getLogger(__name__)

_CSS = """
body{font-family:-apple-system,Segoe UI,Helvetica,Arial,sans-serif;margin:2em auto;
max-width:1100px;color:#222;line-height:1.4;padding:0 1em}
h1{font-size:1.6em;margin-bottom:.2em}
h2{font-size:1.2em;border-bottom:1px solid #ddd;margin-top:1.6em}
table{border-collapse:collapse;margin:.6em 0;font-size:.9em}
td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}th{background:#f3f3f3}
td.l,th.l{text-align:left}
.box{background:#f6f8fa;border:1px solid #d0d7de;padding:.8em 1.2em;border-radius:6px}
.warn{color:#9a6700}.bad{color:#b00}.muted{color:#666;font-size:.85em}
figure{margin:1em 0}figure img{max-width:100%;border:1px solid #eee}
"""


def _e(x: object) -> str:
    return html.escape(str(x))


def _img(png: bytes, caption: str) -> str:
    data = base64.b64encode(png).decode("ascii")
    return (
        f'<figure><img alt="{_e(caption)}" src="data:image/png;base64,{data}">'
        f"<figcaption class=muted>{_e(caption)}</figcaption></figure>"
    )


def _fmt(v: float | None, digits: int = 4) -> str:
    if v is None or not np.isfinite(v):
        return "—"
    return f"{v:.{digits}f}" if abs(v) >= 10 ** (-digits + 1) or v == 0 else f"{v:.3e}"


def _table(head: list[str], rows: list[list[str]], left: int = 1) -> str:
    th = "".join(
        f'<th class="{"l" if i < left else ""}">{_e(h)}</th>'
        for i, h in enumerate(head)
    )
    body = "".join(
        "<tr>"
        + "".join(
            f'<td class="{"l" if i < left else ""}">{c}</td>' for i, c in enumerate(r)
        )
        + "</tr>"
        for r in rows
    )
    return f"<table><tr>{th}</tr>{body}</table>"


# After loading, record how many figures decoded and are visible (``data-figures="k/n"``
# on <html>) and flag broken ones on the page; tests read it with a headless browser.
_CHECK = """<script>window.addEventListener("load",function(){var im=document.images,ok=0;
for(var i=0;i<im.length;i++){var r=im[i].getBoundingClientRect();
if(im[i].complete&&im[i].naturalWidth>0&&r.width>0&&r.height>0){ok++}
else{im[i].insertAdjacentHTML("afterend","<p class=bad>figure failed to load</p>")}}
document.documentElement.setAttribute("data-figures",ok+"/"+im.length);});</script>"""


def _page(title: str, body: str) -> str:
    stamp = time.strftime("%Y-%m-%d %H:%M")
    return (
        f"<!DOCTYPE html><html lang=en><head><meta charset=utf-8><title>{_e(title)}</title>"
        f"<style>{_CSS}</style></head><body><h1>{_e(title)}</h1>"
        f"<p class=muted>kinecal {__version__}, {stamp}</p>{body}{_CHECK}</body></html>\n"
    )


def _write(path: str | Path, text: str) -> Path:
    from kinecal.io import atomic_write_text

    return atomic_write_text(path, text, force=True)


# ---------------------------------------------------------------------- parameter tables
def _frames_table(cal: CalibratedModel) -> str:
    m = cal.model
    L = m.layout
    rows = []
    for which, labels in (("base", m.spec.sets), ("cam", m.spec.markers)):
        E = m.frame_euler(cal.params, which)
        idx = m.base_index if which == "base" else m.cam_index
        for k, lab in enumerate(labels):
            name = ("T_user_base" if which == "base" else "T_flange_cam") + (
                f" [{lab}]" if lab else ""
            )
            cells = [_e(name)]
            for c in range(6):
                v = E[k, c] * (1e3 if c < 3 else 180 / np.pi)
                i = idx[k, c] if c < idx.shape[1] else None
                sd = cal.std[i] * L.to_file[i] if i is not None else np.nan
                cells.append(
                    _fmt(v, 3) + (f" ± {_fmt(sd, 3)}" if np.isfinite(sd) else "")
                )
            rows.append(cells)
    return _table(
        ["frame", "x [mm]", "y [mm]", "z [mm]", "r [deg]", "w [deg]", "p [deg]"], rows
    )


def _dh_table(cal: CalibratedModel) -> str:
    L = cal.model.layout
    fields = [
        ("theta_offset", "θ [deg]"),
        ("d", "d [mm]"),
        ("a", "a [mm]"),
        ("alpha", "α [deg]"),
        ("beta", "β [deg]"),
    ]
    if not any(f"joint{j}.beta" in L for j in range(1, cal.model.n_joints + 1)):
        fields = fields[:4]
    rows = []
    for j in range(1, cal.model.n_joints + 1):
        cells = [f"J{j}"]
        for key, _ in fields:
            name = f"joint{j}.{key}"
            if name in L:
                i = L.index(name)
                v, sd = cal.params[i] * L.to_file[i], cal.std[i] * L.to_file[i]
                tag = (
                    ""
                    if cal.status[i] == "estimated"
                    else f" <span class=warn>({_e(cal.status[i])})</span>"
                )
                cells.append(
                    _fmt(v, 4) + (f" ± {_fmt(sd, 4)}" if np.isfinite(sd) else "") + tag
                )
            else:
                cells.append("—")
        rows.append(cells)
    return _table(["joint"] + [h for _, h in fields], rows)


def _compliance_table(cal: CalibratedModel) -> str:
    L = cal.model.layout
    rows = []
    payload = cal.reference_payload_kg
    for i, s in enumerate(L.specs):
        if s.group not in ("ntm", "load", "link"):
            continue
        if s.kind == "ntm":
            v, sd, unit = cal.params[i] * 1e3, cal.std[i] * 1e3, "10⁻³ rad"
        elif s.kind == "compliance":
            v, sd, unit = (
                cal.params[i] * 1e3,
                cal.std[i] * 1e3,
                "10⁻³ rad/m (per unit weight)",
            )
        else:
            v, sd, unit = (
                cal.params[i] * L.to_file[i],
                cal.std[i] * L.to_file[i],
                s.unit.file_unit,
            )
        extra = ""
        if s.kind == "compliance" and payload:
            extra = f"{cal.params[i] / (payload * 9.80665):.3e} rad/(N·m)"
        rows.append(
            [_e(s.name), _fmt(v, 4), _fmt(sd, 4), _e(unit), extra, _e(cal.status[i])]
        )
    if not rows:
        return "<p class=muted>This model has no compliance terms.</p>"
    return _table(["parameter", "value", "std", "unit", "physical", "status"], rows)


# ---------------------------------------------------------------------- calibration report
def write_calibration_report(
    path: str | Path,
    result: CalibrationResult,
    meas: Measurements,
    summary: dict[str, Any],
) -> Path:
    """``report.html`` of a calibration: summary, tables, figures, identifiability."""
    cal = result.calibrated
    b, a = result.metrics_before, result.metrics_after
    ident = result.identifiability
    warn = "".join(f"<li class=warn>{_e(w)}</li>" for w in result.warnings)
    dropped = (
        "".join(f"<li>{_e(d.describe())}</li>" for d in ident.dropped)
        or "<li>none</li>"
    )
    body = [
        "<div class=box>",
        f"<p><b>{_e(cal.model.robot.name)}</b>, model <b>{_e(cal.model.spec.name)}</b>: "
        f"{ident.rank} of {cal.model.size} parameters estimated from {meas.n} {meas.kind} poses "
        f"({_e(meas.source)}).</p>",
        "<p>Position error on the calibration data: RMS "
        f"<b>{b.rms_mm:.4f} mm → {a.rms_mm:.4f} mm</b>, max {b.max_mm:.4f} mm → "
        f"{a.max_mm:.4f} mm (before: nominal kinematics with fitted user and tool frames). "
        "Validate on poses not used here with <code>kinecal evaluate</code>.</p>",
        f"<p>Not identifiable from these poses (held at their start values):</p><ul>{dropped}</ul>",
        f"<p>{'Converged.' if result.success else '<span class=bad>Did not converge.</span>'}"
        f" Noise estimate {summary.get('noise_sigma_mm', float('nan')):.4f} mm per axis.</p>",
        f"<ul>{warn}</ul>" if warn else "",
        "</div>",
        "<h2>Frames (Tables 3, 6)</h2>",
        _frames_table(cal),
        "<h2>Joint geometry (Tables 4, 7)</h2>",
        _dh_table(cal),
        "<h2>Joint compliance (Tables 4, 7)</h2>",
        _compliance_table(cal),
        "<h2>Stages</h2>",
        _table(
            [
                "stage",
                "parameters",
                "RMS before [mm]",
                "RMS after [mm]",
                "iterations",
                "status",
                "time [s]",
            ],
            [
                [
                    _e(s.name),
                    str(s.n_free),
                    _fmt(s.rms_before_mm),
                    _fmt(s.rms_after_mm),
                    str(s.iterations),
                    _e(s.status),
                    f"{s.seconds:.3f}",
                ]
                for s in result.stages
            ],
        ),
        "<h2>Identifiability</h2><ul>"
        + "".join(f"<li>{_e(x)}</li>" for x in ident.summary())
        + "</ul>",
    ]
    if result.outliers:
        body.append("<h2>Outliers (kept in the data, reported here)</h2>")
        body.append(
            _table(
                ["row", "error [mm]", "z [-]"],
                [
                    [str(o.row), _fmt(o.error_mm), f"{o.z:.1f}"]
                    for o in result.outliers[:50]
                ],
            )
        )
    if F.available():
        body.append("<h2>Figures</h2>")
        body += _calibration_figures(result, meas)
    else:
        body.append(
            "<p class=muted>Figures need matplotlib: pip install 'kinecal[report]'.</p>"
        )
    body.append("<h2>All parameters</h2><details><summary>show</summary>")
    body.append(
        _table(
            ["name", "value", "std", "unit", "start", "status"],
            [
                [
                    _e(p["name"]),
                    _fmt(p["value"], 6),
                    _fmt(p["std"], 6),
                    _e(p["unit"]),
                    _fmt(p["start"], 6),
                    _e(p["status"]),
                ]
                for p in summary["parameters"]
            ],
        )
    )
    body.append("</details>")
    return _write(
        path,
        _page(f"kinecal calibration report: {cal.model.robot.name}", "\n".join(body)),
    )


def _calibration_figures(result: CalibrationResult, meas: Measurements) -> list[str]:
    cal = result.calibrated
    m = cal.model
    inputs = meas.model_inputs(cal.reference_payload_kg)
    before = residuals(m, result.registered, meas, result.weights, inputs=inputs)
    after = residuals(m, cal.params, meas, result.weights, inputs=inputs)
    eb = np.linalg.norm(before.raw_position, axis=1) * 1e3
    ea = np.linalg.norm(after.raw_position, axis=1) * 1e3
    out = [
        _img(
            F.fig_errors_before_after(eb, ea),
            "Position error per pose before and after calibration [mm] (calibration data).",
        )
    ]
    q_deg = np.degrees(meas.q_ctrl)
    out.append(
        _img(
            F.fig_residuals_vs_joints(
                q_deg,
                after.raw_position * 1e3,
                [f"J{j + 1}" for j in range(q_deg.shape[1])],
            ),
            "Residuals after calibration against each controller joint angle.",
        )
    )
    free = np.flatnonzero(result.identifiability.free)
    if free.size > 1:
        corr = result.correlation()[np.ix_(free, free)]
        out.append(
            _img(
                F.fig_correlation(corr, [m.layout.names[i] for i in free]),
                "Correlations of the estimated parameters.",
            )
        )
    sv = result.identifiability.singular_values
    if sv.size:
        out.append(
            _img(
                F.fig_singular_values(sv),
                "Singular values of the scaled identification Jacobian.",
            )
        )
    ref = meas.reference_points() * 1e3
    out.append(
        _img(
            F.fig_workspace(ref, ea),
            "Errors after calibration over the workspace [mm].",
        )
    )
    return out


# ---------------------------------------------------------------------- comparison report
def write_comparison_report(
    path: str | Path,
    rows: list[ComparisonRow],
    test: Measurements,
    *,
    title: str,
    notes: list[str] | None = None,
    extra_html: str = "",
    png_dir: str | Path | None = None,
) -> Path:
    """Report of a model comparison on held-out data (Tables 5, 8 and Figures 11, 15).

    ``png_dir``: also write each figure there as a PNG file (for slides and READMEs).
    """
    pngs: dict[str, bytes] = {}

    def keep(name: str, png: bytes) -> bytes:
        pngs[name] = png
        return png

    from kinecal.report._summary import comparison_table

    table = comparison_table(rows)
    body = ["<div class=box>"]
    if len(rows) >= 2:
        first, last = rows[0], rows[-1]
        body.append(
            f"<p>Held-out RMS error: <b>{first.model} {first.test.rms_mm:.4f} mm → "
            f"{last.model} {last.test.rms_mm:.4f} mm</b> over {last.test.n} poses not used for "
            "calibration.</p>"
        )
    body += [f"<p>{_e(n)}</p>" for n in notes or []]
    body.append("</div><h2>Comparison (Tables 5, 8)</h2>")
    body.append(
        _table(
            [
                "method",
                "model size",
                "estimated",
                "RMS [mm]",
                "Std [mm]",
                "Avg [mm]",
                "Max [mm]",
                "train RMS [mm]",
            ],
            [
                [
                    _e(r["model"]),
                    str(r["size"]),
                    str(r["estimated"]),
                    _fmt(r["rms_mm"]),
                    _fmt(r["std_mm"]),
                    _fmt(r["mean_mm"]),
                    _fmt(r["max_mm"]),
                    _fmt(r["train_rms_mm"]),
                ]
                for r in table
            ],
        )
    )
    body.append(extra_html)
    if F.available():
        errs: dict[str, Float] = {}
        xyz: dict[str, Float] = {}
        for r in rows:
            if r.calibrated is None:
                continue
            blk = r.calibrated.predict(test)
            errs[r.model] = np.linalg.norm(blk.raw_position, axis=1) * 1e3
            xyz[r.model] = blk.raw_position * 1e3
        body.append("<h2>Figures (as Figures 11 and 15)</h2>")
        names = list(errs)
        if len(names) >= 2:
            body.append(
                _img(
                    keep(
                        "a_errors_before_after",
                        F.fig_errors_before_after(
                            errs[names[0]],
                            errs[names[-1]],
                            f"(a) position errors: {names[0]} vs {names[-1]}",
                        ),
                    ),
                    "Held-out position error per point [mm].",
                )
            )
        methods = {k: v for k, v in errs.items() if k != "nominal"}
        body.append(
            _img(
                keep("b_histogram", F.fig_error_histogram(methods)),
                "Histogram of held-out errors per method.",
            )
        )
        body.append(
            _img(
                keep(
                    "c_axis_counts",
                    F.fig_axis_counts({k: v for k, v in xyz.items() if k != "nominal"}),
                ),
                "Counts of held-out errors along x, y, z per method.",
            )
        )
        body.append(
            _img(
                keep("d_violin", F.fig_violin(methods)),
                "Distributions of held-out errors per method.",
            )
        )
        if names:
            body.append(
                _img(
                    keep(
                        "workspace",
                        F.fig_workspace(test.reference_points() * 1e3, errs[names[-1]]),
                    ),
                    f"Held-out errors of {names[-1]} over the workspace [mm].",
                )
            )
    else:
        body.append(
            "<p class=muted>Figures need matplotlib: pip install 'kinecal[report]'.</p>"
        )
    if png_dir is not None and pngs:
        from kinecal.io import atomic_write_bytes

        for name, png in pngs.items():
            atomic_write_bytes(Path(png_dir) / f"{name}.png", png, force=True)
    return _write(path, _page(title, "\n".join(body)))
