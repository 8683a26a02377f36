"""``build_report``: models + records (+ bending planes) -> a :class:`~endocal.report.result.Report`.

The orchestration behind ``endocal report``: load and check the inputs, score every model on
every record of its axis (:mod:`endocal.report.evaluate`), cross-validate every model
structure for the ladder (:mod:`endocal.report.ladder`), find the measured sweeps behind a
planes file (:mod:`endocal.report.planes`), draw the figures (:mod:`endocal.report.figures`)
and collect the provenance. Long work reports through a
``progress(step, done, total)`` callback (the CLI shows it as a rich progress bar on stderr);
the library itself never prints.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from endocal import __version__
from endocal.errors import EndocalError, RunFormatError
from endocal.messages import Message
from endocal.models.data import OTHER_CMD, HysteresisData
from endocal.planes import PlanesCalibration, load_planes
from endocal.planes.halfplanes import NOMINAL_AZIMUTH_DEG
from endocal.report import figures as F
from endocal.report.evaluate import DataEntry, Progress, axis_planes, evaluate, load_inputs
from endocal.report.ladder import ladder_size, model_ladder
from endocal.report.planes import PlanesView, planes_view
from endocal.report.result import Report, ReportFigure, check_output
from endocal.runs.aligned import read_stream
from endocal.runs.format import TRACKER, sha256_of, software_versions, utc_now


def _slug(*parts: str) -> str:
    return "-".join(re.sub(r"[^A-Za-z0-9]+", "_", p).strip("_") for p in parts)


def _other_axis(hdata: HysteresisData) -> tuple[str, np.ndarray] | None:
    other = hdata.extras.get(OTHER_CMD)
    if other is None or float(np.ptp(other)) < 1e-9:
        return None
    return ("other axis command", other)


def _tip_path(d: DataEntry) -> np.ndarray | None:
    """The measured tip in the base sensor's frame (mm), or None for a record that logged no tracker.

    An aligned table, or a run of a rig that measures the angle itself, has no tip path to draw,
    and nothing is missing: only a tracker stream that is there and cannot be read is an error.

    Raises
    ------
    EndocalError
        The record's tracker stream is unreadable or holds no usable pose pair.
    """
    from endocal.planes.segment import tip_in_base_from_tracker

    src = Path(d.aligned.source)
    if not (src / TRACKER).is_dir():
        return None
    _, tip_in_base_mm, _, _ = tip_in_base_from_tracker(read_stream(src, TRACKER), where=d.label)
    return tip_in_base_mm


def _walked_path(d: DataEntry):
    """The tip-path evaluation of a record that walked one (``validate --trajectory``), else None."""
    from endocal.validation.tip_path import evaluate_tip_run

    src = Path(d.aligned.source)
    if not src.is_dir() or "tip_desired_x_mm" not in d.aligned.table.columns:
        return None
    return evaluate_tip_run(src, label=d.label)


def _walk_start(d: DataEntry) -> float:
    return float((d.meta.get("protocol", {}).get("walk_s") or [0.0])[0])


def model_figure(label: str, model, color: str) -> tuple[ReportFigure, callable]:
    """The figure of a fitted model's parameters with their intervals, and the function that draws it.

    Parameters
    ----------
    label : str
        The model's name in the report (its file's stem).
    model : HysteresisModel
        Fitted.
    color : str
        Its colour in the report.
    """
    fixed = getattr(model, "fixed_", {})
    shown = model.parameter_labels()  # an input effect's in the drive's unit: deadzone_slack_mm
    params = {shown[n]: (float(v), None if not np.isfinite(model.stderr_[n]) else float(model.stderr_[n]), n in fixed)
              for n, v in model.params_.items()}
    name = "+".join([model.base_name] + [e.label for e in model.effects_])
    return (ReportFigure(f"params-{_slug(label)}", "models", f"{label}: fitted parameters",
                         "Each parameter with its 95 % interval (1.96 standard errors from the fit's "
                         "Jacobian), relative to its estimate; red: the interval includes zero.", b"", label),
            lambda: F.parameters(params, f"{label} ({model.axis}): {name}", color))


def planes_figure(view: PlanesView) -> tuple[ReportFigure, callable]:
    """The bending-plane figure, titled and captioned for what was measured and what is only fitted,
    and the function that draws it."""
    cal = view.calibration
    b, a = view.before, view.after
    if b is not None:
        t0 = f"before compensation: measured, {b.n_points} tip points of {len(b.sweeps)} sweeps"
    else:
        t0 = "before compensation: FITTED planes only (measured sweeps not found)"
    if a is not None:
        t1 = f"after compensation: measured, {a.n_points} tip points of {len(a.sweeps)} sweeps"
    else:
        t1 = (f"after compensation: NOT measured ({cal.residual_source} prediction)"
              if cal.residual_source != "measured" else "after compensation: recorded residuals, runs not found")
    measured = [x for x in (b, a) if x is not None]
    src = "; ".join(f"{x.phase} compensation from {', '.join(x.runs)}" for x in measured)
    caption = ("Looking down the probe axis (duodenoscope paper, fig. 8): the tip positions of the single-knob sweeps "
               "in the base sensor's frame, projected on its x-y plane, per half-plane (dots); solid lines: each "
               "half-plane's fitted trace (before: fitted deviation, wedge: 95 % interval; after: the residual "
               f"deviation, {cal.residual_source})"
               + (", drawn through the points' centroid: the fitted direction (bend-line model) need not pass "
                  "through the probe axis when the other knob keeps a residual bend" if cal.model == "bend_line" else "")
               + "; dashed: the standard planes. "
               + (f"Measured points: {src}." if measured else "")
               + ("" if b is not None and a is not None else
                  " A panel without dots shows fitted geometry only, no measurement: see the notes above."))
    title = "Bending planes before and after orthogonal compensation"
    if b is None:
        title += " (fitted geometry only)"
    return (ReportFigure("planes", "planes", title, caption, b""),
            lambda: F.planes_figure(None if b is None else b.tip_xy_mm, None if a is None else a.tip_xy_mm,
                             cal.deviation_signed_deg, cal.deviation_signed_ci_deg, cal.residual_deviation_signed_deg,
                             NOMINAL_AZIMUTH_DEG, (t0, t1), title, offset_line=cal.model == "bend_line"))


def record_figures(data: str, signal: str, axis: str, hdata: HysteresisData, predicted: dict[str, np.ndarray],
                   regimes: dict, colors: dict[str, str], *, comparison=None, unit_rmse_deg: dict | None = None,
                   units: str = "unit") -> list[tuple[ReportFigure, callable]]:
    """The report's figures of one record and axis, each with the function that draws it.

    The report draws them for every record group; :meth:`endocal.api.Validation.plot` draws
    the same figures of the record a model was validated on.

    Parameters
    ----------
    data, signal, axis : str
        The record's label, its protocol's signal, and the axis.
    hdata : HysteresisData
        The axis's command, measured angle and time (and the other axis's command).
    predicted : dict of label to (n,) array
        Each model's predicted angle (deg).
    regimes : dict of label to RegimeBreakdown
        Each model's error by regime.
    colors : dict of label to colour
    comparison : Comparison, optional
        The models' paired tests on per-unit errors: with ``unit_rmse_deg`` (label -> per-unit
        RMSE, deg) and ``units`` (their kind), adds the figure of the error per unit.

    Returns
    -------
    list of (ReportFigure, callable)
        The figure's identity and words (``png`` still empty), and a function drawing its
        :class:`matplotlib.figure.Figure`: time series, loops, error per unit (with a
        comparison), residuals, regimes.
    """
    key, slug = f"{data}/{axis}", _slug(data, axis)
    t, cmd, meas = hdata.t_s, hdata.cmd_deg, hdata.meas_deg
    errs = {m: p - meas for m, p in predicted.items()}
    head = f"{data} ({signal}), axis {axis}"
    jobs = [
        (ReportFigure(f"ts-{slug}", "records", f"{head}: time series",
                      "Knob command (dashed), measured bending angle (black) and each model's prediction; below, "
                      "each model's error (predicted - measured).", b"", key),
         lambda: F.time_series(t, cmd, meas, predicted, colors, head, hdata.cmd_unit)),
        (ReportFigure(f"loops-{slug}", "records", f"{head}: hysteresis loops",
                      "Bending angle against knob command: measured, then each model (colour) over the measured "
                      "loop (grey).", b"", key),
         lambda: F.loops(cmd, meas, predicted, colors, head, hdata.cmd_unit)),
    ]
    if comparison is not None:
        jobs.append(
            (ReportFigure(f"box-{slug}", "records", f"{head}: error per {units}",
                          f"RMSE of each {units} per model (dots: units). Brackets: paired Wilcoxon "
                          f"signed-rank tests{' with Holm correction' if comparison.test == 'friedman' else ''}; "
                          "* p < 0.05, ** p < 0.01, *** p < 0.001, ns not significant.", b"", key),
             lambda: F.error_boxes(unit_rmse_deg, comparison, colors, head)))
    jobs += [
        (ReportFigure(f"resid-{slug}", "records", f"{head}: residuals",
                      "Error against knob speed, knob command, the other axis and time (dots: samples; lines: "
                      "mean per bin). A slope against speed points to rate, a step at zero speed to dead zone, "
                      "a trend in time to drift or creep, a slope against the other axis to coupling.", b"", key),
         lambda: F.residuals(t, cmd, _other_axis(hdata), errs, colors, head, hdata.cmd_unit)),
        (ReportFigure(f"regime-{slug}", "records", f"{head}: error by regime",
                      "RMSE of each model by regime of the motion, as `endocal validate` breaks it down: near "
                      "reversals vs steady motion and holds, by speed band (terciles), by amplitude (thirds of "
                      "the half-span), by the other knob's position and over time (quarters).", b"", key),
         lambda: F.regimes(regimes, colors, head)),
    ]
    return jobs


def build_report(
    models: Sequence,
    datas: Sequence,
    planes: str | Path | PlanesCalibration | None = None,
    out: str | Path | None = None,
    *,
    force: bool = False,
    n_boot: int = 400,
    regime_boot: int = 200,
    seed: int = 0,
    progress: Progress | None = None,
    command: str | None = None,
    folds: int = 5,
    planes_runs: Sequence[str | Path] = (),
    keep_figures: bool = False,
    history: str | Path | None = None,
    history_probe: str | None = None,
) -> Report:
    """Evaluate and compare models on records and build the report (optionally writing it).

    Parameters
    ----------
    models : sequence of path or HysteresisModel
        Model files (``endocal fit hysteresis``) or fitted models.
    datas : sequence of path or AlignedData
        Run folders or aligned tables.
    planes : path or PlanesCalibration, optional
        ``planes.json`` (``endocal fit planes``): adds the before/after bending-plane figure.
    out : path, optional
        Write the HTML there, with ``report.json`` and ``report_metrics.csv`` beside it.
    force : bool
        Overwrite existing output files.
    n_boot, seed : int
        Bootstrap replicates and seed of the metric intervals (the defaults of
        :func:`endocal.validation.metrics.error_metrics`, so the numbers equal ``validate``'s).
    regime_boot : int
        Bootstrap replicates of the per-regime intervals (``validate``'s default: 200).
    progress : callable, optional
        ``progress(step, done, total)``.
    command : str, optional
        The command line, recorded in the provenance.
    folds : int
        Held-out blocks of the model ladder's rolling-origin cross-validation (``validate``'s
        default, so the held-out RMSE equals the one it prints).
    planes_runs : sequence of path
        Where else to look for the planes runs (run folders or folders holding them) besides
        the planes file's folder and the records' folders (see :mod:`endocal.report.planes`).
    keep_figures : bool
        Keep each drawn :class:`matplotlib.figure.Figure` as ``ReportFigure.figure`` (for a
        notebook); otherwise only its PNG is kept.
    history : path, optional
        A probe-check history (``endocal check --history DIR``): adds the control charts of the
        probe checked against these models (:func:`endocal.check.summary.report_pages`).
    history_probe : str, optional
        With ``history``: the probe to show, when its checks used other model files.

    Returns
    -------
    Report

    Raises
    ------
    ModelError, RunFormatError
        Missing or invalid inputs, models for axes no record has, records no model applies
        to, or no model that could be evaluated on any record (the message lists why).
    OutputExistsError, OutputPathError
        See :meth:`Report.write`.
    """
    if out is not None:
        check_output(out, force=force)  # refuse before minutes of work, not after
    model_entries, data_entries = load_inputs(models, datas)
    check_pages, check_notes = [], []
    if history is not None:  # read before minutes of work: a bad history is refused at once
        from endocal.check.summary import report_pages

        check_pages, check_notes = report_pages(history, [m.sha256 for m in model_entries], history_probe)
    cal, planes_path = None, None
    if planes is not None:
        if isinstance(planes, PlanesCalibration):
            cal = planes
        else:
            planes_path = Path(planes)
            cal = load_planes(planes_path)

    def stage(offset: int, total: int):
        if progress is None:
            return None
        return lambda step, done, _n: progress(step, offset + done, total)

    # the total grows as the work becomes known: evaluations, then ladder rungs (at most one
    # per evaluation), then figures
    n_eval = sum(1 for d in data_entries for m in model_entries if m.axis in d.aligned.axes)
    n_groups = sum(1 for d in data_entries for a in d.aligned.axes if any(m.axis == a for m in model_entries))
    n_fig_est = 5 * n_groups + len(model_entries) + 2 + (planes is not None)
    # each model is scored through the planes it was fitted through (its file records them);
    # --planes draws the calibration, and stands in for a model's planes file that was moved
    read_planes, off_planes, model_entries = axis_planes(model_entries, moved=planes_path)
    groups, skipped = evaluate(model_entries, data_entries, n_boot=n_boot, regime_boot=regime_boot, seed=seed,
                               progress=stage(0, 2 * n_eval + n_fig_est), planes=read_planes)
    skipped = off_planes + skipped
    if not groups:
        reasons = "; ".join(f"{s.model} on {s.data}: {s.reason}" for s in skipped)
        raise RunFormatError(f"no model could be evaluated on any record ({reasons})")
    n_rungs = ladder_size(model_entries, groups)
    ladder = model_ladder(model_entries, groups, folds=folds, n_boot=n_boot, seed=seed, datas=data_entries,
                          progress=stage(n_eval, n_eval + n_rungs + n_fig_est))
    n_done = n_eval + n_rungs

    colors = F.palette([m.label for m in model_entries])
    data_colors = F.palette([d.label for d in data_entries])
    figs: list[ReportFigure] = []
    notes: list[str] = list(check_notes)
    view: PlanesView | None = None
    if cal is not None:
        places = [Path(d.aligned.source).parent for d in data_entries] + [Path(p) for p in planes_runs]
        view = planes_view(cal, planes_path, places=places)
        notes += [Message(n, "planes-figure") for n in view.notes]  # endocal.report.planes words them
    jobs: list[tuple[str, callable]] = []

    for g in groups:
        signal = next(d.signal for d in data_entries if d.label == g.data)
        jobs += record_figures(g.data, signal, g.axis, g.hdata, {e.model: e.predicted_deg for e in g.evaluations},
                               {e.model: e.regimes for e in g.evaluations}, colors, comparison=g.comparison,
                               unit_rmse_deg={e.model: e.unit_rmse_deg for e in g.evaluations}, units=g.units.kind)
    for axis in dict.fromkeys(s["axis"] for s in ladder):
        steps = [dict(s, model=s["step"]) for s in ladder if s["axis"] == axis]
        if len({s["model"] for s in steps}) >= 2:
            jobs.append((ReportFigure(f"ladder-{_slug(axis)}", "ladder", f"Model ladder, axis {axis}",
                                      f"Each model structure (base, base+effect, ...) scored as `endocal validate` "
                                      f"does: refitted on the model's own training records and run over a record it "
                                      f"never saw, or on a record it was fitted on by rolling origin ({folds} folds): "
                                      "solid, held-out RMSE of data it was not fitted on, with "
                                      "95 % block-bootstrap intervals; dashed, hollow: in-sample RMSE of the same fits "
                                      "on their training data. Stars: the step's held-out gain over the previous "
                                      "step is significant (one-sided paired test, Holm).", b""),
                         lambda steps=steps, axis=axis: F.ladder(steps, data_colors, f"Model ladder, axis {axis}")))
    for m in model_entries:
        jobs.append(model_figure(m.label, m.model, colors[m.label]))
    if view is not None:
        jobs.append(planes_figure(view))
    paths = {}
    for d in data_entries:
        try:
            tip = _tip_path(d)
        except EndocalError as exc:
            notes.append(Message(f"no task-space tip trajectory for {d.label}: {exc}", "no-tip-path"))
            continue
        if tip is not None:
            paths[d.label] = tip
    for d in data_entries:
        walk = _walked_path(d)
        if walk is None:
            continue
        m = walk.metrics
        stops = [e for e in walk.events if e.get("kind") == "stop"]
        stop_s = [float(np.interp(e["t_s"] - _walk_start(d), walk.t_s, walk.s_mm)) for e in stops]
        jobs.append((ReportFigure(f"walk-{_slug(d.label)}", "task-space", f"{d.label}: tip path '{walk.path}'",
                                  f"Desired (dashed) and reached tip (colour: error) in the base sensor's frame at home, "
                                  f"and the error |P_r - P_d| along the path: median {m.median_mm:.2f} mm, RMSE "
                                  f"{m.rmse_mm:.2f} mm, max {m.max_mm:.2f} mm, median {m.path_pct:.2f} % of the "
                                  f"{m.length_mm:.1f} mm path ({m.n} tracker frames).", b""),
                     lambda w=walk, stop_s=stop_s, lbl=d.label: F.tip_path_errors(
                         w.desired_mm, w.reached_mm, w.s_mm, w.error_mm, f"{lbl}: tip path '{w.path}'", stop_s)))
    for d in data_entries:
        for e in d.meta.get("events", []) or []:
            if e.get("kind") == "stop":
                knobs = ", ".join(f"{a} knob at {v:.1f} deg" for a, v in (e.get("knob_deg") or {}).items())
                notes.append(Message(f"force guard stop in {d.label}: t = {e['t_s']:.2f} s, predicted tip force "
                                     f"{e['force_pred_n']:.3f} N (threshold {e['threshold_n']:g} N), {knobs}",
                                     "force-stop"))
    if paths:
        jobs.append((ReportFigure("tip-paths", "task-space", "Task-space tip trajectories",
                                  "Measured tip position in the base sensor's frame (EM tracker), per record.", b""),
                     lambda: F.tip_paths(paths, "Tip trajectories in the base frame")))

    for pid, pc in check_pages:
        from endocal.report.checks import charts_figure

        jobs.append((ReportFigure(f"checks-{_slug(pid)}", "checks", f"Probe {pid}: {pc.state}, {pc.n_checks} checks "
                                  "since calibration",
                                  "Control charts of the probe's checks since its calibration (endocal check): per "
                                  "figure, the individuals chart (limits mu +- 3 sigma from the first 10 checks, shaded), "
                                  "the moving ranges (UCL 3.267 MR-bar) and the EWMA (lambda 0.2, exact limits). Red: "
                                  "a point beyond 3 sigma (out of control); orange: the EWMA beyond its limit "
                                  "(drifting).", b""),
                     lambda pc=pc: charts_figure(pc)))
    total = n_done + len(jobs)
    for k, (fig, draw) in enumerate(jobs, start=1):
        if progress:
            progress(f"figure: {fig.title}", n_done + k, total)
        drawn = draw()
        fig.png = F.to_png(drawn)
        if keep_figures:
            fig.figure = drawn
        figs.append(fig)

    provenance = {
        "endocal_version": __version__,
        "software": software_versions(),
        "created_utc": utc_now(),
        "command": command,
        "bootstrap": {"n_boot": n_boot, "regime_boot": regime_boot, "seed": seed, "confidence": 0.95},
        "ladder_cv": {"scheme": "endocal validate's: estimation/validation on records the model was not fitted on, "
                                "else rolling-origin blocked", "folds": folds},
        "models": [{"label": m.label, "path": None if m.path is None else str(m.path), "sha256": m.sha256,
                    "axis": m.axis, "model": m.name,
                    "training_data": list(getattr(m.model, "training_data_", []) or [])} for m in model_entries],
        "data": [d.to_dict() for d in data_entries],
        "planes": None if cal is None else {"path": None if planes_path is None else str(planes_path),
                                            "sha256": None if planes_path is None else sha256_of(planes_path)},
    }
    report = Report(model_entries, data_entries, groups, skipped, ladder, figs, cal, provenance, notes, view)
    if out is not None:
        report.write(out, force=force)
    return report
