"""The report's figures, drawn with matplotlib's object API.

No ``pyplot``: each function builds and returns its own :class:`matplotlib.figure.Figure` on
an Agg canvas, so nothing leaks into a global figure registry and the functions are safe to
call from any thread or from a program that has its own pyplot state. The report embeds them
as PNG (:func:`to_png`); the Python API (:mod:`endocal.api`) hands the same figures to a
notebook, where they show themselves (:class:`NotebookFigure`). Inputs are plain arrays and
result objects; every number drawn was computed elsewhere (the figures compute nothing the
tables do not show, except bin means that only guide the eye in residual plots).
"""

from __future__ import annotations

import io
from collections.abc import Mapping, Sequence

import numpy as np
from matplotlib import patheffects
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from endocal.report.stats import Comparison, stars

DPI = 110
_PALETTE = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf", "#bcbd22", "#7f7f7f")
MEAS_COLOR = "#222222"
CMD_COLOR = "#9a9a9a"


def palette(labels: Sequence[str]) -> dict[str, str]:
    """One fixed colour per model label, the same in every figure."""
    return {lbl: _PALETTE[i % len(_PALETTE)] for i, lbl in enumerate(labels)}


class NotebookFigure(Figure):
    """A :class:`~matplotlib.figure.Figure` that a notebook shows as its PNG without pyplot.

    IPython draws a plain figure only once pyplot's inline backend has registered itself;
    ``_repr_png_`` lets a figure of the report display wherever it is the cell's value.
    """

    def _repr_png_(self) -> bytes:
        return to_png(self)


def _new(width_in: float, height_in: float) -> Figure:
    fig = NotebookFigure(figsize=(width_in, height_in), dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def to_png(fig: Figure) -> bytes:
    """The figure as PNG bytes, at the report's resolution (``DPI``)."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI)
    return buf.getvalue()


def _thin(n: int, keep: int = 4000) -> np.ndarray:
    """Indices of at most ``keep`` evenly spread samples (scatter plots stay light)."""
    return np.unique(np.linspace(0, n - 1, min(n, keep)).round().astype(int)) if n else np.zeros(0, int)


def time_series(t_s: np.ndarray, cmd_deg: np.ndarray, meas_deg: np.ndarray, predicted: Mapping[str, np.ndarray],
                colors: Mapping[str, str], title: str, cmd_unit: str = "deg") -> Figure:
    """Command, measured and predicted bending angle over time, and each model's error below.

    Parameters
    ----------
    t_s, cmd_deg, meas_deg : (n,) arrays
        Time (s), knob command (``cmd_unit``: deg, or mm for a linear drive) and measured bending
        angle (deg).
    predicted : mapping of label to (n,) array
        Each model's predicted angle (deg).
    colors : mapping of label to colour
    title : str
    """
    fig = _new(10.5, 5.2)
    ax, ax_e = fig.subplots(2, 1, sharex=True, height_ratios=[2, 1])
    # a knob's command shares the angle's axis (both deg); a linear drive's (mm, a few of them against
    # tens of degrees) gets its own axis on the right, or it draws as a flat line at the angle's zero
    ax_cmd = ax if cmd_unit == "deg" else ax.twinx()
    cmd_line, = ax_cmd.plot(t_s, cmd_deg, color=CMD_COLOR, lw=1.0, ls="--", label=f"knob command ({cmd_unit})")
    ax.plot(t_s, meas_deg, color=MEAS_COLOR, lw=1.6, label="measured")
    for lbl, y in predicted.items():
        ax.plot(t_s, y, color=colors[lbl], lw=1.0, label=lbl)
        ax_e.plot(t_s, y - meas_deg, color=colors[lbl], lw=0.8, label=lbl)
    ax_e.axhline(0, color="k", lw=0.6)
    ax.set_ylabel("angle (deg)")
    if ax_cmd is not ax:
        ax_cmd.set_ylabel(f"command ({cmd_unit})", color=CMD_COLOR)
        ax_cmd.tick_params(axis="y", colors=CMD_COLOR)
    ax_e.set_ylabel("error (deg)\npredicted - measured")
    ax_e.set_xlabel("time (s)")
    ax.set_title(title, loc="left", fontsize=11)
    handles = ax.get_legend_handles_labels()[0]
    if ax_cmd is not ax:
        handles = [cmd_line, *handles]
    ax.legend(handles=handles, loc="upper right", fontsize=8, ncols=min(4, 2 + len(predicted)))
    for a in (ax, ax_e):
        a.grid(alpha=0.3)
    return fig


def loops(cmd_deg: np.ndarray, meas_deg: np.ndarray, predicted: Mapping[str, np.ndarray], colors: Mapping[str, str],
          title: str, cmd_unit: str = "deg") -> Figure:
    """Hysteresis loops: measured angle against command (in ``cmd_unit``), then each model's over the measured one."""
    n = 1 + len(predicted)
    ncols = min(n, 4)
    nrows = int(np.ceil(n / ncols))
    fig = _new(2.75 * ncols + 0.5, 2.7 * nrows + 0.4)
    axes = np.atleast_1d(fig.subplots(nrows, ncols, sharex=True, sharey=True, squeeze=False)).ravel()
    axes[0].plot(cmd_deg, meas_deg, color=MEAS_COLOR, lw=0.9)
    axes[0].set_title("measured", fontsize=10)
    for ax, (lbl, y) in zip(axes[1:], predicted.items()):
        ax.plot(cmd_deg, meas_deg, color="#c8c8c8", lw=1.6, label="measured")
        ax.plot(cmd_deg, y, color=colors[lbl], lw=0.9, label=lbl)
        ax.set_title(lbl, fontsize=10, color=colors[lbl])
    for ax in axes[n:]:
        ax.set_visible(False)
    for i, ax in enumerate(axes[:n]):
        ax.grid(alpha=0.3)
        if i % ncols == 0:
            ax.set_ylabel("bending angle (deg)")
        if i >= n - ncols:
            ax.set_xlabel(f"knob command ({cmd_unit})")
    fig.suptitle(title, x=0.01, ha="left", fontsize=11)
    return fig


def error_boxes(unit_rmse_deg: Mapping[str, np.ndarray], comparison: Comparison, colors: Mapping[str, str],
                title: str) -> Figure:
    """Per-unit RMSE of each model as box plots, with significance brackets (thesis fig. 7 style).

    A bracket joins two models whose paired Wilcoxon test (Holm-adjusted when more than two
    models) gives p < 0.05; stars: ``*`` < 0.05, ``**`` < 0.01, ``***`` < 0.001. With two
    models the bracket is drawn either way, marked ``ns`` when not significant.
    """
    labels = list(unit_rmse_deg)
    fig = _new(max(4.5, 1.3 * len(labels) + 2.0), 4.2)
    ax = fig.subplots()
    data = [np.asarray(unit_rmse_deg[m], float) for m in labels]
    bp = ax.boxplot(data, tick_labels=labels, widths=0.55, patch_artist=True, showfliers=False,
                    medianprops={"color": "k"})
    for patch, lbl in zip(bp["boxes"], labels):
        patch.set_facecolor(colors[lbl])
        patch.set_alpha(0.35)
    rng = np.random.default_rng(0)
    for i, (lbl, y) in enumerate(zip(labels, data), start=1):
        ax.scatter(i + rng.uniform(-0.12, 0.12, y.size), y, s=12, color=colors[lbl], zorder=3)
    top = max((float(np.max(y)) for y in data if y.size), default=1.0)
    step = 0.09 * top if top > 0 else 0.1
    level = top + 0.5 * step
    pairs = [p for p in comparison.pairs if p.significant(comparison.alpha) or len(labels) == 2]
    pairs.sort(key=lambda p: abs(labels.index(p.a) - labels.index(p.b)))
    for p in pairs:
        i, j = sorted((labels.index(p.a) + 1, labels.index(p.b) + 1))
        ax.plot([i, i, j, j], [level, level + 0.3 * step, level + 0.3 * step, level], color="k", lw=0.9)
        ax.text((i + j) / 2, level + 0.35 * step, stars(p.p_adjusted), ha="center", va="bottom", fontsize=10)
        level += step
    ax.set_ylim(0, level + 0.6 * step)
    ax.set_ylabel(f"RMSE per {comparison.unit_kind} (deg)")
    test = {"wilcoxon": "Wilcoxon signed-rank", "friedman": "Friedman + Holm-corrected Wilcoxon",
            "none": "no test"}[comparison.test]
    ax.set_title(f"{title}\n{comparison.n_units} {comparison.unit_kind}s; {test}", loc="left", fontsize=10)
    ax.grid(axis="y", alpha=0.3)
    ax.tick_params(axis="x", labelrotation=15 if len(labels) > 3 else 0)
    return fig


def residuals(t_s: np.ndarray, cmd_deg: np.ndarray, other: tuple[str, np.ndarray] | None,
              errors: Mapping[str, np.ndarray], colors: Mapping[str, str], title: str, cmd_unit: str = "deg") -> Figure:
    """Each model's error (predicted - measured) against knob speed, command, other axis and time.

    Dots are a thinned sample of the error; lines are the mean error in 20 bins, which is where
    a missing effect shows: a slope against speed (rate), a step at zero speed (dead zone), a
    trend over time (drift), a slope against the other axis (coupling).

    Parameters
    ----------
    other : (name, (n,) array) or None
        The other axis's command to plot against (None: that panel says the axis did not move).
    cmd_unit : str
        The command's unit (deg, or mm for a linear drive).
    """
    speed = np.gradient(cmd_deg, t_s) if cmd_deg.size > 1 else np.zeros_like(cmd_deg)
    xs = [(f"knob speed ({cmd_unit}/s)", speed), (f"knob command ({cmd_unit})", cmd_deg),
          (f"{other[0]} (deg)" if other else "other axis", other[1] if other else None), ("time (s)", t_s)]
    fig = _new(10.5, 6.2)
    axes = fig.subplots(2, 2, sharey=True).ravel()
    idx = _thin(cmd_deg.size, 3000)
    for ax, (xlabel, x) in zip(axes, xs):
        ax.axhline(0, color="k", lw=0.6)
        ax.set_xlabel(xlabel)
        ax.grid(alpha=0.3)
        if x is None:
            ax.text(0.5, 0.5, "the other axis does not move in this record", ha="center", va="center",
                    transform=ax.transAxes, fontsize=9, color="#555")
            continue
        edges = np.linspace(float(np.min(x)), float(np.max(x)), 21)
        which = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, 19)
        centres = 0.5 * (edges[1:] + edges[:-1])
        for lbl, e in errors.items():
            ax.scatter(x[idx], e[idx], s=2, color=colors[lbl], alpha=0.12, rasterized=True, linewidths=0)
            counts = np.bincount(which, minlength=20)
            sums = np.bincount(which, weights=e, minlength=20)
            ok = counts >= 5
            ax.plot(centres[ok], sums[ok] / counts[ok], color=colors[lbl], lw=1.6, label=lbl)
    for ax in axes[::2]:
        ax.set_ylabel("error (deg)")
    axes[0].legend(fontsize=8, loc="upper left")
    fig.suptitle(title, x=0.01, ha="left", fontsize=11)
    return fig


def regimes(rows: Mapping[str, object], colors: Mapping[str, str], title: str) -> Figure:
    """RMSE per regime of motion, one bar per model.

    Parameters
    ----------
    rows : mapping of label to RegimeBreakdown
        :func:`endocal.validation.regimes.error_by_regime` of each model.
    """
    labels = list(rows)
    keys: list[tuple[str, str]] = []
    for lbl in labels:
        for r in rows[lbl].regimes:
            if (r.group, r.name) not in keys:
                keys.append((r.group, r.name))
    fig = _new(10.5, 0.05 * len(keys) * max(2, len(labels)) + 0.12 * len(keys) + 1.0)
    ax = fig.subplots()
    h = 0.8 / max(1, len(labels))
    for j, lbl in enumerate(labels):
        by = {(r.group, r.name): r for r in rows[lbl].regimes}
        y = [i + (j - (len(labels) - 1) / 2) * h for i in range(len(keys))]
        v = [by[k].metrics.rmse_deg if k in by else np.nan for k in keys]
        ax.barh(y, v, height=h, color=colors[lbl], label=lbl)
    ax.set_yticks(range(len(keys)), [f"{g}: {n}" for g, n in keys], fontsize=8)
    ax.invert_yaxis()
    fam = [k[0] for k in keys]
    for i in range(1, len(keys)):
        if fam[i] != fam[i - 1]:
            ax.axhline(i - 0.5, color="#999", lw=0.6)
    ax.set_xlabel("RMSE (deg)")
    ax.grid(axis="x", alpha=0.3)
    ax.legend(fontsize=8, loc="lower right")
    ax.set_title(title, loc="left", fontsize=10)
    return fig


def ladder(steps: Sequence[dict], colors_by_data: Mapping[str, str], title: str) -> Figure:
    """The model ladder: held-out and in-sample RMSE of base, base+effect, ... on each record.

    Parameters
    ----------
    steps : sequence of dict
        From :func:`endocal.report.ladder.model_ladder`, with ``model`` the x label (in ladder
        order): ``data``, ``heldout_rmse_deg`` (None: not cross-validated), ``heldout_ci``,
        ``train_rmse_deg`` and ``p_adjusted`` / ``significant`` of the step's held-out gain.
    colors_by_data : mapping of record label to colour
    """
    order: list[str] = []
    for s in steps:
        if s["model"] not in order:
            order.append(s["model"])
    fig = _new(max(5.5, 1.5 * len(order) + 3.0), 4.4)
    ax = fig.subplots()
    datas = list(dict.fromkeys(s["data"] for s in steps))
    top = 0.0
    for k, d in enumerate(datas):
        pts = [s for s in steps if s["data"] == d and s["heldout_rmse_deg"] is not None]
        if not pts:
            continue
        x = np.array([order.index(s["model"]) for s in pts], float) + (k - (len(datas) - 1) / 2) * 0.08
        held = np.array([s["heldout_rmse_deg"] for s in pts])
        train = np.array([s["train_rmse_deg"] for s in pts])
        c = colors_by_data[d]
        ax.plot(x, held, color=c, lw=1.6, marker="o", ms=6, label=f"{d}: held-out")
        ax.plot(x, train, color=c, lw=1.0, ls="--", marker="o", ms=5, mfc="white", label=f"{d}: in-sample")
        for xi, s in zip(x, pts):
            if s.get("heldout_ci"):
                lo, hi = s["heldout_ci"]
                ax.plot([xi, xi], [lo, hi], color=c, lw=1.0)
                top = max(top, hi)
            if s.get("p_adjusted") is not None:
                ax.annotate(stars(s["p_adjusted"]), (xi, s["heldout_rmse_deg"]), xytext=(6, 4),
                            textcoords="offset points", fontsize=8, color=c)
        top = max(top, float(np.max(held)), float(np.max(train)))
    ax.set_xticks(range(len(order)), order, rotation=12 if len(order) > 3 else 0)
    ax.set_ylim(0, 1.12 * top if top > 0 else 1.0)
    ax.set_ylabel("RMSE (deg)")
    ax.grid(axis="y", alpha=0.3)
    ax.legend(fontsize=7.5, ncols=max(1, len(datas)))
    ax.set_title(title, loc="left", fontsize=10)
    return fig


def parameters(params: Mapping[str, tuple[float, float | None, bool]], title: str, color: str) -> Figure:
    """Fitted parameters with 95 % intervals, each relative to its own estimate.

    Parameters have different units, so each row shows ``(value +- 1.96 SE) / |value|``: a bar
    that stays clear of 0 is a well-identified parameter, one that crosses 0 is not
    distinguishable from zero, an absent bar means an infinite (unidentified) or unknown error.

    Parameters
    ----------
    params : mapping of name to (value, stderr or None, fixed)
    """
    names = list(params)
    fig = _new(7.8, 0.26 * len(names) + 1.2)
    ax = fig.subplots()
    for i, n in enumerate(names):
        v, se, fixed = params[n]
        if fixed:
            ax.scatter([1.0], [i], marker="s", color="#999", s=18)
            continue
        if abs(v) <= 1e-6 * max(1.0, se or 0.0):  # at a zero bound (e.g. a PI weight): no relative scale
            ax.scatter([0.0], [i], marker="o", color=color, s=14)
            if se is not None and np.isfinite(se):
                ax.text(0.05, i, f"0 +- {se:.2g}", va="center", fontsize=7, color="#555")
            continue
        rel = 1.96 * se / abs(v) if se is not None and np.isfinite(se) else None
        centre = np.sign(v)
        if rel is not None:
            lo, hi = centre - rel, centre + rel
            crosses = lo <= 0 <= hi
            ax.plot([max(lo, -3), min(hi, 3)], [i, i], color="#d62728" if crosses else color, lw=2)
            for end, edge in ((lo, -3.0), (hi, 3.0)):
                if abs(end) > 3:
                    ax.scatter([edge], [i], marker="<" if edge < 0 else ">", color="#d62728" if crosses else color, s=16)
        ax.scatter([centre], [i], color=color, s=14, zorder=3)
    ax.set_yticks(range(len(names)), [f"{n} = {params[n][0]:.4g}" + (" (fixed)" if params[n][2] else
                                      f" +- {params[n][1]:.2g}" if params[n][1] is not None else " +- ?")
                                      for n in names], fontsize=7)
    ax.invert_yaxis()
    ax.axvline(0, color="k", lw=0.6)
    ax.set_xlim(-3.1, 3.1)
    ax.set_xlabel("estimate with 95 % interval, relative to |estimate| (red: interval includes 0)")
    ax.grid(axis="x", alpha=0.3)
    ax.set_title(title, loc="left", fontsize=10)
    return fig


_HALF_COLORS = {"y+": "#1f77b4", "y-": "#2ca02c", "x+": "#d62728", "x-": "#ff7f0e"}


def _planes_panel(ax, points_mm: Mapping[str, np.ndarray] | None, signed_deg: Mapping[str, float],
                  ci_deg: Mapping[str, tuple[float, float]] | None, nominal_azimuth_deg: Mapping[str, float],
                  title: str, offset_line: bool, radius: float) -> None:
    """One panel of :func:`planes_figure`: measured points (if any), fitted half-plane lines, standard planes."""
    r = radius
    lim = 1.12 * r
    ax.plot([-lim, lim], [0, 0], color="#777", ls="--", lw=0.9, zorder=1)
    ax.plot([0, 0], [-lim, lim], color="#777", ls="--", lw=0.9, zorder=1, label="standard planes")
    for h, nom in nominal_azimuth_deg.items():
        c = _HALF_COLORS.get(h, "k")
        dev = float(signed_deg[h])
        shown = round(dev, 2) + 0.0  # + 0.0: no "-0.00" in the legend
        if points_mm:
            p = points_mm[h]
            ax.scatter(p[:, 0], p[:, 1], s=3, color=c, alpha=0.35, linewidths=0, rasterized=True, zorder=2,
                       label=f"{h}: {len(p)} points")
        u = np.array([np.cos(np.radians(nom + dev)), np.sin(np.radians(nom + dev))])
        start, length = np.zeros(2), r
        if points_mm and offset_line and len(points_mm[h]):
            # bend_line fit: the trace is a direction, the sweep may sit off the axis (the other
            # knob's residual bend); draw it along the points, through their centroid
            centre = points_mm[h].mean(axis=0)
            along = (points_mm[h] - centre) @ u
            start, length = centre + u * along.min(), float(np.ptp(along))
        if ci_deg is not None:
            a = np.radians(nom + np.linspace(ci_deg[h][0], ci_deg[h][1], 20))
            ax.fill(start[0] + np.r_[0, length * np.cos(a), 0], start[1] + np.r_[0, length * np.sin(a), 0],
                    color=c, alpha=0.18, lw=0, zorder=1)
        end = start + length * u
        ax.plot([start[0], end[0]], [start[1], end[1]], color=c, lw=1.3, zorder=3,
                path_effects=[patheffects.Stroke(linewidth=2.4, foreground="k"), patheffects.Normal()],
                label=f"{h} fitted: {shown:+.2f} deg" if not points_mm else f"{h} fit {shown:+.2f} deg")
    ax.set_aspect("equal")
    ax.set_xlim(-lim, lim)
    ax.set_ylim(-lim, lim)
    if points_mm:
        ax.set_xlabel("tip x in base frame (mm)")
        ax.set_ylabel("tip y in base frame (mm)")
    else:
        ax.set_xlabel("x in base frame (fitted directions only, no measured points)")
        ax.set_ylabel("y in base frame")
    ax.set_title(title, fontsize=9.5, loc="left")
    ax.legend(fontsize=6.5, loc="lower left", markerscale=3, ncols=2)
    ax.grid(alpha=0.3)


def planes_figure(before_mm: Mapping[str, np.ndarray] | None, after_mm: Mapping[str, np.ndarray] | None,
                  deviation_signed_deg: Mapping[str, float], deviation_ci_deg: Mapping[str, tuple[float, float]],
                  residual_signed_deg: Mapping[str, float], nominal_azimuth_deg: Mapping[str, float],
                  titles: tuple[str, str], title: str, offset_line: bool = False) -> Figure:
    """Bending planes seen down the probe axis, before and after orthogonal compensation (duodenoscope fig. 8).

    Each panel scatters the measured tip positions of the single-knob sweeps (base frame,
    projected on its x-y plane, mm), draws each half-plane's fitted trace (solid; before: the fitted signed deviation with its 95 % interval as a wedge; after: the
    residual deviation) and the standard planes (dashed). A panel without measured points
    draws the fitted lines only, at the other panel's scale, and its title must say so.

    Parameters
    ----------
    before_mm, after_mm : mapping of half-plane to (n, 2) array, or None
        Measured tip x-y (mm) per half-plane; None when not measured or not found.
    deviation_signed_deg, deviation_ci_deg : mappings
        Fitted signed deviations and their intervals (deg).
    residual_signed_deg : mapping
        Signed deviation left after compensation (deg).
    nominal_azimuth_deg : mapping
        Azimuth of each standard half-plane (deg).
    titles : (str, str)
        Panel titles (they carry what each panel shows: measured or fitted only).
    title : str
    offset_line : bool
        The fit is a direction that need not pass through the probe axis (``bend_line``
        model): with measured points, each trace is drawn along its points, through their
        centroid; otherwise from the probe axis (the paper's plane through it).

    Returns
    -------
    Figure
    """
    fig = _new(10.5, 5.6)
    axes = fig.subplots(1, 2)
    # one scale for both panels: the farthest measured point (lines-only panels borrow it)
    radius = max((float(np.max(np.hypot(p[:, 0], p[:, 1]))) for pts in (before_mm, after_mm) if pts
                  for p in pts.values() if len(p)), default=1.0)
    _planes_panel(axes[0], before_mm, deviation_signed_deg, deviation_ci_deg, nominal_azimuth_deg, titles[0],
                  offset_line, radius)
    _planes_panel(axes[1], after_mm, residual_signed_deg, None, nominal_azimuth_deg, titles[1], offset_line,
                  radius)
    fig.suptitle(title, x=0.01, ha="left", fontsize=11)
    return fig


def tip_paths(paths_mm: Mapping[str, np.ndarray], title: str) -> Figure:
    """Measured tip trajectories in the base sensor's frame: top view (x-y) and side view (x-z, y-z)."""
    fig = _new(10.5, 3.8)
    axes = fig.subplots(1, 3)
    views = (("x_mm", "y_mm", 0, 1), ("x_mm", "z_mm", 0, 2), ("y_mm", "z_mm", 1, 2))
    cols = _PALETTE
    for k, (lbl, p) in enumerate(paths_mm.items()):
        idx = _thin(p.shape[0], 6000)
        for ax, (xl, yl, i, j) in zip(axes, views):
            ax.scatter(p[idx, i], p[idx, j], s=1.5, color=cols[k % len(cols)], label=lbl, rasterized=True, linewidths=0)
    for ax, (xl, yl, _, _) in zip(axes, views):
        ax.set_xlabel(xl.replace("_mm", " (mm)"))
        ax.set_ylabel(yl.replace("_mm", " (mm)"))
        ax.set_aspect("equal", adjustable="datalim")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7, markerscale=5)
    fig.suptitle(title, x=0.01, ha="left", fontsize=11)
    return fig


def tip_path_errors(desired_mm: np.ndarray, reached_mm: np.ndarray, s_mm: np.ndarray, error_mm: np.ndarray,
                    title: str, stops_s_mm: Sequence[float] = ()) -> Figure:
    """A walked tip path: desired (dashed) and reached tip seen from above, and the error along the path.

    ``stops_s_mm``: where along the path the contact-force guard stopped the bending (marked).
    """
    fig = _new(10.5, 3.8)
    top, along = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1, 1.6]})
    top.plot(desired_mm[:, 0], desired_mm[:, 1], "--", color="0.35", lw=1.2, label="desired")
    sc = top.scatter(reached_mm[:, 0], reached_mm[:, 1], c=error_mm, s=3, cmap="viridis", linewidths=0, label="reached")
    fig.colorbar(sc, ax=top, label="error (mm)", fraction=0.046, pad=0.04)
    top.set_xlabel("x (mm)")
    top.set_ylabel("y (mm)")
    top.set_aspect("equal", adjustable="datalim")
    top.grid(alpha=0.3)
    top.legend(fontsize=7, markerscale=3, loc="upper right")
    along.plot(s_mm, error_mm, color=_PALETTE[0], lw=0.9)
    med = float(np.median(error_mm))
    along.axhline(med, color="0.3", ls=":", lw=1, label=f"median {med:.2f} mm")
    for k, s in enumerate(stops_s_mm):
        along.axvline(s, color="#d62728", lw=0.8, alpha=0.7, label="force guard stop" if k == 0 else None)
    along.set_xlabel("distance along the path (mm)")
    along.set_ylabel("|P_r - P_d| (mm)")
    along.grid(alpha=0.3)
    along.legend(fontsize=7)
    fig.suptitle(title, x=0.01, ha="left", fontsize=11)
    return fig
