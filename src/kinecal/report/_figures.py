"""Figures (matplotlib, an optional extra), returned as PNG bytes.

The comparison figures follow the paper's Figures 11 and 15: (a) position error per point
before and after calibration, (b) histogram of error counts per method, (c) per-direction
error counts per method as a 3-D bar chart, (d) violin plot of the error distributions.
Diagnostics: residuals against each joint angle, parameter correlations, singular values
of the scaled identification Jacobian, errors over the workspace in 3-D.
"""

from __future__ import annotations

import io
from collections.abc import Sequence

import numpy as np

from kinecal.typing import Float

__all__ = [
    "available",
    "fig_axis_counts",
    "fig_correlation",
    "fig_error_histogram",
    "fig_errors_before_after",
    "fig_residuals_vs_joints",
    "fig_singular_values",
    "fig_violin",
    "fig_workspace",
]

_COLORS = ["#7f7f7f", "#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b"]


def available() -> bool:
    """True when matplotlib can be imported."""
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        return False
    return True


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _png(fig) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
    _plt().close(fig)
    return buf.getvalue()


def fig_errors_before_after(
    before_mm: Float, after_mm: Float, title: str = ""
) -> bytes:
    """(a) 3-D position error of each point before and after calibration [mm]."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7.5, 3.4))
    idx = np.arange(before_mm.size)
    ax.scatter(idx, before_mm, s=6, color=_COLORS[0], label="before (nominal)")
    ax.scatter(idx, after_mm, s=6, color=_COLORS[1], label="after (calibrated)")
    ax.set_xlabel("point index")
    ax.set_ylabel("position error [mm]")
    ax.set_yscale("log")
    ax.set_title(title or "(a) position error before and after calibration")
    ax.legend(loc="upper right", fontsize=8)
    ax.grid(alpha=0.3, which="both")
    return _png(fig)


def fig_error_histogram(errors_mm: dict[str, Float]) -> bytes:
    """(b) histogram of error counts per method [mm]."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7.5, 3.4))
    hi = max(float(np.percentile(e, 99.5)) for e in errors_mm.values())
    bins = np.linspace(0.0, hi, 30)
    for k, (name, e) in enumerate(errors_mm.items()):
        ax.hist(
            e,
            bins=bins,
            histtype="step",
            lw=1.6,
            color=_COLORS[(k + 1) % len(_COLORS)],
            label=name,
        )
    ax.set_xlabel("position error [mm]")
    ax.set_ylabel("count [points]")
    ax.set_title("(b) count of position errors")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    return _png(fig)


def fig_axis_counts(errors_xyz_mm: dict[str, Float]) -> bytes:
    """(c) error counts per direction (x, y, z) and method, as a 3-D bar chart."""
    plt = _plt()
    fig = plt.figure(figsize=(7.5, 4.6))
    ax = fig.add_subplot(projection="3d")
    names = list(errors_xyz_mm)
    allv = np.concatenate([np.abs(v).ravel() for v in errors_xyz_mm.values()])
    hi = float(np.percentile(allv, 99.5))
    edges = np.linspace(0.0, hi, 9)
    width = edges[1] - edges[0]
    for m, name in enumerate(names):
        e = np.abs(errors_xyz_mm[name])
        for a in range(3):
            counts, _ = np.histogram(e[:, a], bins=edges)
            ys = np.full(counts.size, m * 3 + a)
            ax.bar3d(
                edges[:-1],
                ys,
                np.zeros(counts.size),
                width * 0.8,
                0.8,
                counts,
                color=_COLORS[(m + 1) % len(_COLORS)],
                alpha=0.35 + 0.2 * a,
                shade=True,
            )
    ax.set_yticks([m * 3 + 1 for m in range(len(names))])
    ax.set_yticklabels(names, fontsize=7)
    ax.set_xlabel("|error| along x, y, z [mm]", fontsize=8)
    ax.set_zlabel("count [points]", fontsize=8)
    ax.set_title(
        "(c) count of errors in each direction (light to dark: x, y, z)", fontsize=9
    )
    return _png(fig)


def fig_violin(errors_mm: dict[str, Float]) -> bytes:
    """(d) violin plot of the error distributions [mm]."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7.5, 3.4))
    names = list(errors_mm)
    parts = ax.violinplot(
        [errors_mm[n] for n in names], showmedians=True, showextrema=True
    )
    for k, body in enumerate(parts["bodies"]):
        body.set_facecolor(_COLORS[(k + 1) % len(_COLORS)])
        body.set_alpha(0.5)
    ax.set_xticks(np.arange(1, len(names) + 1))
    ax.set_xticklabels(names)
    ax.set_ylabel("position error [mm]")
    ax.set_title("(d) error distribution")
    ax.grid(alpha=0.3, axis="y")
    return _png(fig)


def fig_residuals_vs_joints(q_deg: Float, res_mm: Float, names: Sequence[str]) -> bytes:
    """Residual components [mm] against each joint angle [deg]: where Fourier terms show."""
    plt = _plt()
    n = q_deg.shape[1]
    cols = 3
    rows = int(np.ceil(n / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(9, 2.5 * rows), squeeze=False)
    for j in range(rows * cols):
        ax = axes[j // cols][j % cols]
        if j >= n:
            ax.axis("off")
            continue
        for a, lab in enumerate("xyz"):
            ax.scatter(
                q_deg[:, j],
                res_mm[:, a],
                s=4,
                alpha=0.6,
                color=_COLORS[a + 1],
                label=lab,
            )
        ax.set_xlabel(f"{names[j]} [deg]", fontsize=8)
        ax.set_ylabel("residual [mm]", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
        if j == 0:
            ax.legend(fontsize=7, markerscale=2)
    fig.suptitle(
        "residuals against joint angles (calibration data, after)", fontsize=10
    )
    fig.tight_layout()
    return _png(fig)


def fig_correlation(corr: Float, names: Sequence[str]) -> bytes:
    """Correlation matrix of the estimated parameters."""
    plt = _plt()
    k = len(names)
    size = min(3.0 + 0.16 * k, 11.0)
    fig, ax = plt.subplots(figsize=(size, size * 0.85))
    im = ax.imshow(corr, vmin=-1, vmax=1, cmap="coolwarm")
    ax.set_xticks(range(k))
    ax.set_yticks(range(k))
    fs = max(4, 8 - k // 12)
    ax.set_xticklabels(names, rotation=90, fontsize=fs)
    ax.set_yticklabels(names, fontsize=fs)
    fig.colorbar(im, ax=ax, shrink=0.7, label="correlation [-]")
    ax.set_title("parameter correlations")
    return _png(fig)


def fig_singular_values(sv: Float) -> bytes:
    """Singular values of the scaled, column-normalised identification Jacobian."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6.5, 3.0))
    ax.semilogy(np.arange(1, sv.size + 1), sv / sv[0], "o-", ms=3)
    ax.set_xlabel("index [-]")
    ax.set_ylabel("s_i / s_max [-]")
    ax.set_title(f"singular values (condition number {sv[0] / sv[-1]:.3g})")
    ax.grid(alpha=0.3, which="both")
    return _png(fig)


def fig_workspace(p_user_mm: Float, err_mm: Float, title: str = "") -> bytes:
    """Errors over the workspace: measured points coloured by their error [mm]."""
    plt = _plt()
    fig = plt.figure(figsize=(6.5, 5.0))
    ax = fig.add_subplot(projection="3d")
    sc = ax.scatter(
        p_user_mm[:, 0], p_user_mm[:, 1], p_user_mm[:, 2], c=err_mm, s=5, cmap="viridis"
    )
    ax.set_xlabel("x [mm]", fontsize=8)
    ax.set_ylabel("y [mm]", fontsize=8)
    ax.set_zlabel("z [mm]", fontsize=8)
    fig.colorbar(sc, ax=ax, shrink=0.6, label="position error [mm]")
    ax.set_title(title or "errors over the workspace (user frame)", fontsize=9)
    return _png(fig)
