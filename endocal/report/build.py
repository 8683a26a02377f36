"""``build_report``: models + records (+ bending planes) -> a :class:`~endocal.report.result.Report`.

The orchestration behind ``endocal report``: load and check the inputs, score every model on
every record of its axis (:mod:`endocal.report.evaluate`), draw the figures
(:mod:`endocal.report.figures`) and collect the provenance. Long work reports through a
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
from endocal.models.data import OTHER_CMD
from endocal.planes import PlanesCalibration, load_planes
from endocal.planes.halfplanes import NOMINAL_AZIMUTH_DEG
from endocal.report import figures as F
from endocal.report.evaluate import DataEntry, Group, ModelEntry, Progress, evaluate, load_inputs
from endocal.report.result import Report, ReportFigure, check_output
from endocal.runs.aligned import read_stream
from endocal.runs.format import TRACKER, sha256_of, software_versions, utc_now


def _slug(*parts: str) -> str:
    return "-".join(re.sub(r"[^A-Za-z0-9]+", "_", p).strip("_") for p in parts)


def model_ladder(models: list[ModelEntry], groups: list[Group]) -> list[dict]:
    """Steps of the model ladder: per axis, the models ordered by number of effects, scored on each record.

    Models of one base come together (``pi``, ``pi+envelope``, ``pi+envelope+rate``...), bases
    in the order first given; within a base, fewer effects first. Each step carries the
    RMSE, its 95 % interval and whether the record was in the model's training data (then
    the step is in-sample, not held out).

    Returns
    -------
    list of dict with ``axis``, ``model``, ``step`` (name drawn on the axis), ``base``,
    ``n_effects``, ``data``, ``rmse_deg``, ``ci``, ``in_sample``, ``change_pct`` (against the
    previous step of the same base on the same record, None for the first).
    """
    steps = []
    for axis in dict.fromkeys(m.axis for m in models):
        ms = [m for m in models if m.axis == axis]
        bases = list(dict.fromkeys(m.base for m in ms))
        given = {m.label: i for i, m in enumerate(ms)}
        ms = sorted(ms, key=lambda m: (bases.index(m.base), len(m.effects), given[m.label]))
        names = [m.name for m in ms]
        unique = len(set(names)) == len(names)
        for g in (g for g in groups if g.axis == axis):
            prev: dict[str, float] = {}
            for m in ms:
                try:
                    e = g.evaluation(m.label)
                except KeyError:
                    continue
                ci = e.metrics.ci.get("rmse_deg")
                before = prev.get(m.base)
                steps.append({
                    "axis": axis, "model": m.label, "step": m.name if unique else m.label, "base": m.base,
                    "n_effects": len(m.effects), "data": g.data, "rmse_deg": e.metrics.rmse_deg,
                    "ci": None if ci is None else [ci[0], ci[1]], "in_sample": e.in_sample,
                    "change_pct": None if before is None or before == 0 else 100.0 * (e.metrics.rmse_deg - before) / before,
                })
                prev[m.base] = e.metrics.rmse_deg
    return steps


def _other_axis(g: Group) -> tuple[str, np.ndarray] | None:
    other = g.hdata.extras.get(OTHER_CMD)
    if other is None or float(np.ptp(other)) < 1e-9:
        return None
    return ("other axis command", other)


def _tip_path(d: DataEntry) -> np.ndarray:
    from endocal.planes.segment import tip_in_base_from_tracker

    src = Path(d.aligned.source)
    if not src.is_dir():
        raise RunFormatError(f"{d.label} is an aligned table: no tracker stream to draw the tip from")
    _, tip_in_base_mm, _, _ = tip_in_base_from_tracker(read_stream(src, TRACKER), where=d.label)
    return tip_in_base_mm


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

    n_eval = sum(1 for d in data_entries for m in model_entries if m.axis in d.aligned.axes)
    n_groups = sum(1 for d in data_entries for a in d.aligned.axes if any(m.axis == a for m in model_entries))
    n_fig_est = 5 * n_groups + len(model_entries) + 2 + (planes is not None)
    total = n_eval + n_fig_est
    groups, skipped = evaluate(model_entries, data_entries, n_boot=n_boot, regime_boot=regime_boot, seed=seed, progress=stage(0, total))
    if not groups:
        reasons = "; ".join(f"{s.model} on {s.data}: {s.reason}" for s in skipped)
        raise RunFormatError(f"no model could be evaluated on any record ({reasons})")

    colors = F.palette([m.label for m in model_entries])
    data_colors = F.palette([d.label for d in data_entries])
    ladder = model_ladder(model_entries, groups)
    figs: list[ReportFigure] = []
    notes: list[str] = []
    jobs: list[tuple[str, callable]] = []

    for g in groups:
        key = f"{g.data}/{g.axis}"
        t, cmd, meas = g.hdata.t_s, g.hdata.cmd_deg, g.hdata.meas_deg
        preds = {e.model: e.predicted_deg for e in g.evaluations}
        errs = {m: p - meas for m, p in preds.items()}
        signal = next(d.signal for d in data_entries if d.label == g.data)
        head = f"{g.data} ({signal}), axis {g.axis}"
        jobs += [
            (ReportFigure(f"ts-{_slug(g.data, g.axis)}", "records", f"{head}: time series",
                          "Knob command (dashed), measured bending angle (black) and each model's prediction; below, "
                          "each model's error (predicted - measured).", b"", key),
             lambda t=t, cmd=cmd, meas=meas, preds=preds, head=head: F.time_series(t, cmd, meas, preds, colors, head)),
            (ReportFigure(f"loops-{_slug(g.data, g.axis)}", "records", f"{head}: hysteresis loops",
                          "Bending angle against knob command: measured, then each model (colour) over the measured "
                          "loop (grey).", b"", key),
             lambda cmd=cmd, meas=meas, preds=preds, head=head: F.loops(cmd, meas, preds, colors, head)),
            (ReportFigure(f"box-{_slug(g.data, g.axis)}", "records", f"{head}: error per {g.units.kind}",
                          f"RMSE of each {g.units.kind} per model (dots: units). Brackets: paired Wilcoxon "
                          f"signed-rank tests{' with Holm correction' if g.comparison.test == 'friedman' else ''}; "
                          "* p < 0.05, ** p < 0.01, *** p < 0.001, ns not significant.", b"", key),
             lambda g=g, head=head: F.error_boxes({e.model: e.unit_rmse_deg for e in g.evaluations}, g.comparison,
                                                  colors, head)),
            (ReportFigure(f"resid-{_slug(g.data, g.axis)}", "records", f"{head}: residuals",
                          "Error against knob speed, knob command, the other axis and time (dots: samples; lines: "
                          "mean per bin). A slope against speed points to rate, a step at zero speed to dead zone, "
                          "a trend in time to drift or creep, a slope against the other axis to coupling.", b"", key),
             lambda g=g, t=t, cmd=cmd, errs=errs, head=head: F.residuals(t, cmd, _other_axis(g), errs, colors, head)),
            (ReportFigure(f"regime-{_slug(g.data, g.axis)}", "records", f"{head}: error by regime",
                          "RMSE of each model by regime of the motion, as `endocal validate` breaks it down: near "
                          "reversals vs steady motion and holds, by speed band (terciles), by amplitude (thirds of "
                          "the half-span), by the other knob's position and over time (quarters).", b"", key),
             lambda g=g, head=head: F.regimes({e.model: e.regimes for e in g.evaluations}, colors, head)),
        ]
    for axis in dict.fromkeys(s["axis"] for s in ladder):
        steps = [s for s in ladder if s["axis"] == axis]
        if len({s["model"] for s in steps}) >= 2:
            jobs.append((ReportFigure(f"ladder-{_slug(axis)}", "ladder", f"Model ladder, axis {axis}",
                                      "RMSE of each model ordered by its number of effects (base, base+effect, ...), "
                                      "per record, with 95 % block-bootstrap intervals. Filled: held-out record; "
                                      "hollow: the model was fitted on this record (in-sample).", b""),
                         lambda steps=[dict(s, model=s["step"]) for s in steps]: F.ladder(steps, data_colors,
                                                                                        f"Model ladder, axis {axis}")))
    for m in model_entries:
        fixed = getattr(m.model, "fixed_", {})
        params = {n: (float(v), None if not np.isfinite(m.model.stderr_[n]) else float(m.model.stderr_[n]), n in fixed)
                  for n, v in m.model.params_.items()}
        jobs.append((ReportFigure(f"params-{_slug(m.label)}", "models", f"{m.label}: fitted parameters",
                                  "Each parameter with its 95 % interval (1.96 standard errors from the fit's "
                                  "Jacobian), relative to its estimate; red: the interval includes zero.", b"", m.label),
                     lambda m=m, params=params: F.parameters(params, f"{m.label} ({m.axis}): {m.name}", colors[m.label])))
    if cal is not None:
        jobs.append((ReportFigure("planes", "planes", "Bending planes before and after orthogonal compensation",
                                  "Single-knob sweeps of the four half-planes seen from the base (duodenoscope paper, "
                                  "fig. 8): before compensation each leaves along its fitted deviation (wedge: 95 % "
                                  "interval); after, along the residual deviation "
                                  f"({cal.residual_source}). Dashed: the standard planes.", b""),
                     lambda: F.planes(cal.deviation_signed_deg, cal.deviation_signed_ci_deg,
                                      cal.residual_deviation_signed_deg, NOMINAL_AZIMUTH_DEG,
                                      "Bending planes (deviation angles, deg)")))
    paths = {}
    for d in data_entries:
        try:
            paths[d.label] = _tip_path(d)
        except EndocalError as exc:
            notes.append(f"no task-space tip trajectory for {d.label}: {exc}")
    if paths:
        jobs.append((ReportFigure("tip-paths", "task-space", "Task-space tip trajectories",
                                  "Measured tip position in the base sensor's frame (EM tracker), per record.", b""),
                     lambda: F.tip_paths(paths, "Tip trajectories in the base frame")))

    total = n_eval + len(jobs)
    for k, (fig, draw) in enumerate(jobs, start=1):
        if progress:
            progress(f"figure: {fig.title}", n_eval + k, total)
        fig.png = draw()
        figs.append(fig)

    provenance = {
        "endocal_version": __version__,
        "software": software_versions(),
        "created_utc": utc_now(),
        "command": command,
        "bootstrap": {"n_boot": n_boot, "regime_boot": regime_boot, "seed": seed, "confidence": 0.95},
        "models": [{"label": m.label, "path": None if m.path is None else str(m.path), "sha256": m.sha256,
                    "axis": m.axis, "model": m.name,
                    "training_data": list(getattr(m.model, "training_data_", []) or [])} for m in model_entries],
        "data": [d.to_dict() for d in data_entries],
        "planes": None if cal is None else {"path": None if planes_path is None else str(planes_path),
                                            "sha256": None if planes_path is None else sha256_of(planes_path)},
    }
    report = Report(model_entries, data_entries, groups, skipped, ladder, figs, cal, provenance, notes)
    if out is not None:
        report.write(out, force=force)
    return report
