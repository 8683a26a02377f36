"""Scoring every model on every record it applies to: the numbers the report renders.

:func:`load_inputs` checks that the models and the data fit together (the report refuses
models whose axis no record has and records no model applies to). :func:`evaluate` predicts
each record's measured bending angle from its knob command with each model of that axis,
scores the error with :func:`endocal.validation.metrics.error_metrics` (the same call, with
the same defaults, that ``endocal validate`` makes), cuts the record into units and compares
the models statistically (:mod:`endocal.report.stats`). A model that cannot be evaluated on a
record becomes a :class:`NotEvaluated` entry that says why; nothing is dropped silently.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from endocal.errors import EndocalError, ModelError, RunFormatError
from endocal.messages import Message
from endocal.models import HysteresisData, HysteresisModel, load_model
from endocal.report.adapters import RegimeBreakdown, axis_data, error_by_regime, predict_extrapolated
from endocal.report.stats import Comparison, Units, compare_models, make_units, unit_rmse
from endocal.runs.aligned import AlignedData, load_aligned
from endocal.runs.format import sha256_of
from endocal.validation.data import min_cmd_span
from endocal.validation.metrics import ErrorMetrics, error_metrics


Progress = Callable[[str, int, int], None]


@dataclass
class ModelEntry:
    """A model given to the report.

    Attributes
    ----------
    label : str
        Short unique name (the file stem).
    model : HysteresisModel
    path : Path or None
    sha256 : str or None
        Hash of the model file.
    """

    label: str
    model: HysteresisModel
    path: Path | None = None
    sha256: str | None = None

    @property
    def axis(self) -> str:
        return str(self.model.axis)

    @property
    def base(self) -> str:
        return self.model.base_name

    @property
    def effects(self) -> list[str]:
        return [e.label for e in self.model.effects_]

    @property
    def name(self) -> str:
        """``base+effect+effect``, how the model ladder names a step."""
        return "+".join([self.base] + self.effects)

    def to_dict(self) -> dict:
        fit = self.model.fit_report_
        return {
            "label": self.label, "path": None if self.path is None else str(self.path), "sha256": self.sha256,
            "axis": self.axis, "base": self.base, "effects": self.effects, "equation": self.model.equation(),
            "drive_unit": self.model.drive_unit_,
            "parameters": {n: {"value": float(v), "stderr": _finite(self.model.stderr_[n]),
                               "fixed": n in getattr(self.model, "fixed_", {})}
                           for n, v in self.model.params_.items()},
            "fit": None if fit is None else fit.to_dict(),
        }


@dataclass
class DataEntry:
    """A record given to the report.

    Attributes
    ----------
    label : str
        Short unique name (run folder or file stem).
    aligned : AlignedData
    signal : str
        The protocol's signal (``damped-sine``, ``triangle``...) or ``table`` for a bare table.
    """

    label: str
    aligned: AlignedData
    signal: str

    @property
    def meta(self) -> dict:
        return self.aligned.meta

    def to_dict(self) -> dict:
        meta = self.meta
        proto = meta.get("protocol", {}) if isinstance(meta.get("protocol"), dict) else {}
        t = self.aligned.t_s
        return {
            "label": self.label, "path": str(self.aligned.source), "sha256": self.aligned.sha256,
            "signal": self.signal, "protocol": proto.get("name"), "protocol_params": proto.get("params"),
            "seed": meta.get("seed"), "backend": (meta.get("backend") or {}).get("name"),
            "started_utc": meta.get("started_utc"), "software": meta.get("software"),
            "axes": list(self.aligned.axes), "n_samples": int(t.size), "duration_s": float(t[-1] - t[0]),
        }


@dataclass
class Evaluation:
    """One model scored on one record.

    Attributes
    ----------
    model, data, axis : str
        Labels and axis.
    metrics : ErrorMetrics
        Of ``predicted - measured`` (``error_metrics(measured, predicted)``).
    in_sample : bool
        The record is one the model was fitted on (its fingerprint is in the model file).
    unit_rmse_deg : (n_units,) array
        Per-unit RMSE on the group's units.
    regimes : RegimeBreakdown
        Error by regime of the motion (:func:`endocal.validation.regimes.error_by_regime`).
    predicted_deg : (n,) array
        The prediction (for figures; not serialised).
    notes : list of str
        What the reader should know (e.g. commands beyond the fitted range).
    """

    model: str
    data: str
    axis: str
    metrics: ErrorMetrics
    in_sample: bool
    unit_rmse_deg: np.ndarray
    regimes: RegimeBreakdown
    predicted_deg: np.ndarray
    notes: list[str] = field(default_factory=list)

    def to_dict(self) -> dict:
        return {"model": self.model, "data": self.data, "axis": self.axis, "metrics": self.metrics.to_dict(),
                "in_sample": self.in_sample, "unit_rmse_deg": [float(x) for x in self.unit_rmse_deg],
                "regimes": self.regimes.to_dict(), "notes": list(self.notes)}


@dataclass(frozen=True)
class NotEvaluated:
    """A model that could not be scored on a record, and why."""

    model: str
    data: str
    axis: str
    reason: str

    def to_dict(self) -> dict:
        return {"model": self.model, "data": self.data, "axis": self.axis, "reason": self.reason}


@dataclass
class Finding:
    """The summary of one record and axis: best model, by how much, significant or not."""

    data: str
    signal: str
    axis: str
    best: str
    best_rmse_deg: float
    runner_up: str | None
    runner_up_rmse_deg: float | None
    margin_deg: float | None
    margin_pct: float | None
    significant: bool | None
    p_value: float | None
    test: str
    effect_size: float | None
    sentence: str

    def to_dict(self) -> dict:
        return dict(self.__dict__)


@dataclass
class Group:
    """The models of one axis evaluated on one record, and their comparison."""

    data: str
    axis: str
    units: Units
    evaluations: list[Evaluation]
    comparison: Comparison
    finding: Finding
    hdata: HysteresisData

    def evaluation(self, model: str) -> Evaluation:
        for e in self.evaluations:
            if e.model == model:
                return e
        raise KeyError(model)

    def to_dict(self) -> dict:
        return {"data": self.data, "axis": self.axis, "units": self.units.to_dict(),
                "evaluations": [e.to_dict() for e in self.evaluations], "comparison": self.comparison.to_dict(),
                "finding": self.finding.to_dict()}


def _finite(x) -> float | None:
    x = float(x)
    return x if np.isfinite(x) else None


def _unique_labels(names: list[str]) -> list[str]:
    out, seen = [], {}
    for n in names:
        seen[n] = seen.get(n, 0) + 1
    count: dict[str, int] = {}
    for n in names:
        if seen[n] > 1:
            count[n] = count.get(n, 0) + 1
            out.append(f"{n}#{count[n]}")
        else:
            out.append(n)
    return out


def load_inputs(models: Sequence, datas: Sequence) -> tuple[list[ModelEntry], list[DataEntry]]:
    """Load model files and records and check that they fit together.

    Parameters
    ----------
    models : sequence of path or HysteresisModel
        Model files (``endocal fit hysteresis`` output) or fitted models.
    datas : sequence of path or AlignedData
        Run folders or aligned tables (Parquet/CSV), or loaded tables.

    Returns
    -------
    models, datas : lists of ModelEntry and DataEntry

    Raises
    ------
    ModelError
        No model, a missing or invalid model file, a model without an axis, a model
        whose axis no record has, or a model of a drive in another unit than a record's.
    RunFormatError
        No record, a missing or malformed record, or a record none of whose axes any
        model is for.
    """
    if not models:
        raise ModelError("no model given: pass at least one MODEL.json (from `endocal fit hysteresis`)")
    if not datas:
        raise RunFormatError("no data given: pass run folders or aligned tables with --data")
    m_items, m_names = [], []
    for m in models:
        if isinstance(m, HysteresisModel):
            m._require_fitted()
            m_items.append((m, None, None))
            m_names.append(f"{m.base_name}{'+' + '+'.join(e.label for e in m.effects_) if m.effects_ else ''}")
        else:
            p = Path(m)
            model = load_model(p)
            m_items.append((model, p, sha256_of(p)))
            m_names.append(p.stem)
    entries = [ModelEntry(lbl, m, p, h) for lbl, (m, p, h) in zip(_unique_labels(m_names), m_items)]
    for e in entries:
        if not e.model.axis:
            where = e.path or e.label
            raise ModelError(f"{where}: the model records no axis; refit it with --axis so the report knows what data it predicts")

    d_items, d_names = [], []
    for d in datas:
        a = d if isinstance(d, AlignedData) else load_aligned(d)
        d_items.append(a)
        src = Path(a.source)
        d_names.append(src.name if src.is_dir() else src.stem)
    dentries = []
    for lbl, a in zip(_unique_labels(d_names), d_items):
        proto = a.meta.get("protocol") if isinstance(a.meta.get("protocol"), dict) else {}
        dentries.append(DataEntry(lbl, a, str(proto.get("signal") or proto.get("name") or "table")))

    data_axes = sorted({ax for d in dentries for ax in d.aligned.axes})
    for e in entries:
        if e.axis not in data_axes:
            raise ModelError(f"model {e.path or e.label} was fitted on axis '{e.axis}' but no data has it "
                             f"(data axes: {', '.join(data_axes)}); give records of that axis or models fitted on "
                             f"{' or '.join(data_axes)}")
    for e in entries:  # a model of a knob (deg) predicts no linear drive's record (mm), nor the reverse
        for d in dentries:
            if e.axis in d.aligned.axes:
                try:
                    e.model.check_drive_unit(d.aligned.drive_unit(e.axis), f"data {d.aligned.source}")
                except ModelError as exc:
                    raise ModelError(f"model {e.path or e.label}: {exc}") from None
    model_axes = {e.axis for e in entries}
    for d in dentries:
        if not model_axes & set(d.aligned.axes):
            raise RunFormatError(f"data {d.aligned.source} has axes {', '.join(d.aligned.axes)} but the models are for "
                                 f"{', '.join(sorted(model_axes))}: no overlap, nothing to evaluate")
    return entries, dentries


def _in_sample(model: HysteresisModel, data: HysteresisData) -> bool:
    trained = {t.get("sha256") for t in getattr(model, "training_data_", []) or []}
    return any(fp["sha256"] in trained for fp in data.fingerprint())


def _finding(data: DataEntry, axis: str, evs: list[Evaluation], comp: Comparison) -> Finding:
    ranked = sorted(evs, key=lambda e: e.metrics.rmse_deg)
    best = ranked[0]
    fitted_on = [e.model for e in evs if e.in_sample]
    head = f"{data.label} ({data.signal}), {axis}"
    if fitted_on:
        head += f" [in-sample for {', '.join(fitted_on)}]" if len(fitted_on) < len(evs) else " [in-sample: every model was fitted on it]"
    head += ": "
    if len(ranked) == 1:
        return Finding(data.label, data.signal, axis, best.model, best.metrics.rmse_deg, None, None, None, None, None,
                       None, comp.test, None,
                       head + f"only {best.model} was evaluated (RMSE {best.metrics.rmse_deg:.3f} deg)")
    run = ranked[1]
    margin = run.metrics.rmse_deg - best.metrics.rmse_deg
    pct = 100.0 * margin / run.metrics.rmse_deg if run.metrics.rmse_deg > 0 else 0.0
    pair = comp.pair(best.model, run.model)
    text = (head + f"{best.model} is best (RMSE {best.metrics.rmse_deg:.3f} deg), {margin:.3f} deg ({pct:.1f} %) "
            f"below {run.model} ({run.metrics.rmse_deg:.3f} deg); ")
    if pair is None:
        sig, p, eff = None, None, None
        text += "not tested: " + comp.why
    else:
        # effect oriented so that r > 0 means the best model has the smaller errors
        sig, p = pair.significant(comp.alpha), pair.p_adjusted
        eff = pair.rank_biserial if pair.b == best.model else -pair.rank_biserial
        adj = ", Holm-adjusted" if comp.test == "friedman" else ""
        if sig and pair.better == best.model:
            text += f"significant (Wilcoxon on {comp.n_units} {comp.unit_kind}s, p = {p:.2g}{adj}, rank-biserial r = {eff:.2f})"
        else:
            text += f"not significant (Wilcoxon on {comp.n_units} {comp.unit_kind}s, p = {p:.2g}{adj}, rank-biserial r = {eff:.2f})"
            sig = False
            # smallest p an exact signed-rank test on n units can give, after Holm's first step
            p_floor = len(comp.pairs) * 2.0 / 2.0 ** comp.n_units
            if p_floor >= comp.alpha:
                text += (f"; with {comp.n_units} units and {len(comp.pairs)} pair(s) no p-value can fall below "
                         f"{min(p_floor, 1.0):.2g}: record more cycles to decide")
    return Finding(data.label, data.signal, axis, best.model, best.metrics.rmse_deg, run.model, run.metrics.rmse_deg,
                   margin, pct, sig, p, comp.test, eff, text)


def axis_planes(models: list[ModelEntry], given=None, *, moved=None) -> tuple[dict, list[NotEvaluated], list[ModelEntry]]:
    """The bending planes each axis's records are read through, and the models that fit them.

    ``given`` (a planes file or calibration) applies to every model, as ``validate --planes``
    does; otherwise each model brings the planes it was fitted through (recorded in its file,
    found and unchanged: :func:`endocal.validation.estimation.recorded_planes`). Models of one
    axis fitted through other planes than the first of that axis would be scored on other
    angles: they are not evaluated, with the reason. ``moved`` (the report's ``--planes``) stands
    in for a model's recorded planes file that is not found where it was, when it is that file.

    Returns
    -------
    planes : dict
        Axis -> ``(PlanesCalibration or None, path or None)``.
    skipped : list of NotEvaluated
    kept : list of ModelEntry
    """
    from endocal.validation.estimation import recorded_planes

    out: dict = {}
    skipped, kept = [], []
    for m in models:
        if given is not None and not isinstance(given, (str, Path)):  # a PlanesCalibration object
            cal, path = given, "the given planes"
        else:
            cal, path = recorded_planes(m.model, m.path, given, moved=moved)
        key = None if path is None else str(Path(path).resolve())
        if m.axis not in out:
            out[m.axis] = (cal, path, key)
        if out[m.axis][2] != key:
            first = out[m.axis][1] or "no planes"
            skipped.append(NotEvaluated(m.label, "every record", m.axis,
                                        f"fitted through {path or 'no planes'}, while the first model of axis "
                                        f"{m.axis} was fitted through {first}: they would be scored on different "
                                        "angles; report them separately or give --planes"))
            continue
        kept.append(m)
    return {a: (c, p) for a, (c, p, _) in out.items()}, skipped, kept


def evaluate(
    models: list[ModelEntry],
    datas: list[DataEntry],
    *,
    n_boot: int = 400,
    regime_boot: int = 200,
    seed: int = 0,
    progress: Progress | None = None,
    planes: dict | None = None,
) -> tuple[list[Group], list[NotEvaluated]]:
    """Score every model on every record of its axis and compare the models per record.

    Parameters
    ----------
    models, datas : from :func:`load_inputs`
    planes : dict, optional
        Axis -> ``(PlanesCalibration or None, label)``: the bending planes the records of that
        axis are read through (:func:`axis_planes`), so each model is scored on the angles it
        was fitted on, as ``endocal validate`` does.
    n_boot : int
        Bootstrap replicates of the metric intervals (``error_metrics``' default: 400).
    regime_boot : int
        Bootstrap replicates of the per-regime intervals (``error_by_regime``'s default: 200).
    seed : int
        Seed of the bootstrap (``error_metrics``' default: 0).
    progress : callable, optional
        ``progress(step, done, total)`` after each model x record.

    Returns
    -------
    groups : list of Group
        One per record and axis with at least one evaluated model.
    not_evaluated : list of NotEvaluated
    """
    jobs = [(d, m) for d in datas for m in models if m.axis in d.aligned.axes]
    skipped: list[NotEvaluated] = []
    for d in datas:
        for m in models:
            if m.axis not in d.aligned.axes:
                skipped.append(NotEvaluated(m.label, d.label, m.axis,
                                            f"{d.label} has no axis '{m.axis}' (it has {', '.join(d.aligned.axes)})"))
    groups: list[Group] = []
    done = 0
    for d in datas:
        for axis in [a for a in d.aligned.axes if any(m.axis == a for m in models)]:
            cal = (planes or {}).get(axis, (None, None))[0]
            try:
                hd = axis_data(d.aligned, axis, planes=cal)
            except EndocalError as exc:
                for m in (m for m in models if m.axis == axis):
                    skipped.append(NotEvaluated(m.label, d.label, axis, str(exc)))
                continue
            span = float(np.ptp(hd.cmd_deg))
            preds: dict[str, tuple[np.ndarray, list[str]]] = {}
            for m in (m for m in models if m.axis == axis):
                done += 1
                if progress:
                    progress(f"{m.label} on {d.label}", done, len(jobs))
                if span < min_cmd_span(hd):
                    skipped.append(NotEvaluated(m.label, d.label, axis,
                                                f"the {axis} command spans only {span:.2f} {hd.cmd_unit} in {d.label}: "
                                                "the record "
                                                "does not excite this axis"))
                    continue
                try:
                    # as `endocal validate` does: beyond the fitted range the model continues, counted
                    pred, beyond = predict_extrapolated(m.model, hd)
                except EndocalError as exc:
                    skipped.append(NotEvaluated(m.label, d.label, axis, str(exc)))
                    continue
                notes = []
                if beyond:
                    lo, hi = m.model.cmd_range_deg_
                    notes.append(Message(f"{beyond} samples of {d.label} command beyond {m.label}'s fitted range "
                                         f"[{lo:.3g}, {hi:.3g}] {m.model.drive_unit_}: predicted by continuing the "
                                         "model there (an extrapolation)", "beyond-range"))
                preds[m.label] = (np.asarray(pred, float), notes)
            if not preds:
                continue
            units = make_units(hd, [p - hd.meas_deg for p, _ in preds.values()])
            evs = []
            for m in (m for m in models if m.label in preds):
                pred, notes = preds[m.label]
                evs.append(Evaluation(
                    model=m.label, data=d.label, axis=axis,
                    metrics=error_metrics(hd.meas_deg, pred, n_boot=n_boot, seed=seed),
                    in_sample=_in_sample(m.model, hd),
                    unit_rmse_deg=unit_rmse(hd.meas_deg, pred, units),
                    regimes=error_by_regime(hd, pred, n_boot=regime_boot, seed=seed),
                    predicted_deg=pred, notes=notes,
                ))
            comp = compare_models({e.model: e.unit_rmse_deg for e in evs}, units)
            groups.append(Group(d.label, axis, units, evs, comp, _finding(d, axis, evs, comp), hd))
    return groups, skipped
