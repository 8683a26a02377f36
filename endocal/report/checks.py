"""A probe's control charts (endocal check) as one figure: per figure, the individuals, moving-range and EWMA charts."""

from __future__ import annotations

import numpy as np

from endocal.check.charts import BASELINE_CHECKS, ProbeCharts

_OUT = "#c0392b"
_DRIFT = "#e67e22"
_LINE = "#34495e"
_LIMIT = "#7f8c8d"


def charts_figure(pc: ProbeCharts, title: str | None = None):
    """Draw every figure's I, MR and EWMA charts, one row per figure.

    Parameters
    ----------
    pc : ProbeCharts
        The charts of one probe's checks since its calibration.
    title : str, optional

    Returns
    -------
    matplotlib.figure.Figure
        Points beyond the individuals limits in red, EWMA points beyond its limits in orange;
        the shaded checks set the limits.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    from endocal.report.figures import DPI, NotebookFigure

    names = list(pc.charts)
    height_in = 1.9 * max(1, len(names)) + 0.9
    # a fixed layout: the constrained one costs seconds on 30 axes
    fig = NotebookFigure(figsize=(12, height_in), dpi=DPI)
    FigureCanvasAgg(fig)
    fig.subplots_adjust(left=0.09, right=0.985, top=1 - 0.85 / height_in, bottom=0.5 / height_in, hspace=0.3,
                        wspace=0.22)
    axes = fig.subplots(max(1, len(names)), 3, squeeze=False, sharex=True)
    for row, name in zip(axes, names):
        c = pc.charts[name]
        k = np.arange(1, c.x.size + 1)
        for ax in row:
            ax.axvspan(0.5, min(BASELINE_CHECKS, c.x.size) + 0.5, color="#ecf0f1", zorder=0)
            ax.grid(alpha=0.3)
        ax_i, ax_mr, ax_z = row
        ax_i.plot(k, c.x, "o-", color=_LINE, ms=3, lw=1)
        if c.ready:
            ax_i.axhline(c.mu, color=_LIMIT, lw=1)
            ax_i.plot(k, c.i_lo, "--", color=_LIMIT, lw=1)
            ax_i.plot(k, c.i_hi, "--", color=_LIMIT, lw=1)
            bad = c.beyond_i
            ax_i.plot(k[bad], c.x[bad], "o", color=_OUT, ms=5)
            ax_mr.axhline(c.mr_ucl, color=_LIMIT, ls="--", lw=1)
            ax_mr.axhline(c.mr_bar, color=_LIMIT, lw=1)
            ax_z.axhline(c.mu, color=_LIMIT, lw=1)
            ax_z.plot(k, c.z, "o-", color=_LINE, ms=3, lw=1)
            ax_z.plot(k, c.z_lo, "--", color=_LIMIT, lw=1)
            ax_z.plot(k, c.z_hi, "--", color=_LIMIT, lw=1)
            drift = c.beyond_ewma
            ax_z.plot(k[drift], c.z[drift], "o", color=_DRIFT, ms=5)
        ax_mr.plot(k, c.mr, "o-", color=_LINE, ms=3, lw=1)
        ax_i.set_ylabel(name, fontsize=8)
    axes[0][0].set_title("individuals (limits mu +- 3 sigma)", fontsize=9)
    axes[0][1].set_title("moving range (UCL 3.267 MR-bar)", fontsize=9)
    axes[0][2].set_title("EWMA (lambda 0.2, exact limits)", fontsize=9)
    for ax in axes[-1]:
        ax.set_xlabel("check since calibration")
    fig.suptitle(title or f"probe {pc.probe_id}: {pc.state}, {pc.n_checks} checks since calibration", fontsize=11,
                 y=1 - 0.2 / height_in)
    return fig
