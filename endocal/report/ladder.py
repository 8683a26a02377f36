"""The model ladder: does each added effect pay on data the model was not fitted on?

A rung is one model structure (``base + effects``, with the model file's settings), scored
by the scheme ``endocal validate`` uses (:func:`endocal.validation.estimation.plan_estimation`):

**Estimation/validation** when the model file names the records it was fitted on (found and
unchanged) and the record scored is not one of them: the structure is refitted on that
estimation data (decimated as validate's scan does) and run over the whole record, which it
has never seen; its in-sample RMSE is that fit's error on the estimation data.

**Rolling origin** otherwise (the model was fitted on this record, or records nothing): on
every record of its axis the structure is refitted and scored by the blocked rolling-origin
cross-validation that ``endocal validate`` uses for its held-out RMSE and its effect scan
(:mod:`endocal.validation.scan`): the first half of the record only trains, the rest is
cut into ``folds`` contiguous test blocks, fold ``k`` is fitted on everything before block
``k`` and predicts block ``k`` with the history it really had. The calls are those of
``validate`` (:func:`~endocal.validation.folds.fold_bounds`,
:func:`~endocal.validation.folds.heldout_errors`, same folds and decimation), so a rung's
held-out RMSE equals the one ``validate`` prints for that model on that record.

Beside it, the **in-sample** RMSE of the *same* fold fits on their own training prefixes:
in-sample error falls with every parameter added, held-out error only when the effect is
real, and the gap between them is the overfit. Each rung's held-out errors are tested
against the previous rung on the same record (ladder order: models of one base together,
fewer effects first) with the one-sided paired test ``validate`` runs under the same scheme:
on the validation record, the sign-flip test on its units (half-cycles, or decorrelation
blocks; :func:`~endocal.validation.paired.unit_test`); under rolling origin, the block test of
the effect scan (:func:`~endocal.validation.paired.paired_test`: Diebold-Mariano loss
differentials averaged over blocks of three correlation times, Wilcoxon signed-rank). Holm-
corrected over the steps of one record.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from endocal.errors import EndocalError
from endocal.models import HysteresisData, HysteresisModel
from endocal.report.adapters import predict_extrapolated
from endocal.report.evaluate import Group, ModelEntry
from endocal.report.stats import holm
from endocal.validation.metrics import ErrorMetrics, error_metrics
from endocal.validation.data import axis_data
from endocal.validation.estimation import plan_estimation
from endocal.validation.folds import check_cv_data, fold_bounds, fold_split, heldout_errors
from endocal.validation.paired import paired_test, unit_test
from endocal.validation.parallel import one_blas_thread
from endocal.validation.predict import predict_errors
from endocal.validation.scan import MAX_SCAN_SAMPLES, check_fit_data
from endocal.validation.structure import effect_labels, fitted_on, split_fit
from endocal.validation.units import make_units

#: Held-out blocks and the longest record scored undecimated: ``endocal validate``'s defaults
#: (``--folds``, ``max_scan_samples``), so the ladder's held-out RMSE is the one validate prints.
FOLDS = 5
MAX_CV_SAMPLES = MAX_SCAN_SAMPLES


@dataclass
class HeldOut:
    """One model structure cross-validated on one record.

    Attributes
    ----------
    metrics : ErrorMetrics
        Of the held-out predictions (the record's second half, fold by fold), with
        block-bootstrap intervals; ``metrics.rmse_deg`` is the held-out RMSE (deg).
    train_rmse_deg : float
        In-sample RMSE of the same fold fits on their training prefixes, pooled (deg).
    errors_deg : (n_heldout,) array
        Held-out ``predicted - measured`` (deg), for the paired tests; not serialised.
    folds, stride, n_samples : int
        Test blocks, decimation step and samples cross-validated (split scheme: 0 folds, the
        estimation data's decimation step, the validation record's samples).
    scheme : str
        ``rolling-origin`` or ``estimation/validation``.
    """

    metrics: ErrorMetrics
    train_rmse_deg: float
    errors_deg: np.ndarray
    folds: int
    stride: int
    n_samples: int
    scheme: str = "rolling-origin"


def split_validate(model: HysteresisModel, train: HysteresisData, val: HysteresisData, *,
                   max_samples: int = MAX_CV_SAMPLES, n_boot: int = 400, seed: int = 0) -> HeldOut:
    """Refit ``model``'s structure on estimation data ``train`` and score it on ``val`` (never seen).

    As ``endocal validate``'s estimation/validation scan: estimation data decimated to about
    ``max_samples``, validation record run from its start at full rate.

    Raises
    ------
    ModelError
        The estimation data cannot be fitted.
    """
    check_fit_data(train, "estimation data")
    stride = max(1, math.ceil(train.n_samples / max_samples))
    with one_blas_thread():
        fitted = model if fitted_on(model, train) else split_fit(model, effect_labels(model), train, stride)
    err = predict_errors(fitted, val)
    dt = train.decimate(stride) if stride > 1 else train
    train_err = predict_errors(fitted, dt)
    return HeldOut(metrics=error_metrics(val.meas_deg, val.meas_deg + err, n_boot=n_boot, seed=seed),
                   train_rmse_deg=float(np.sqrt(np.mean(train_err**2))), errors_deg=err, folds=0, stride=stride,
                   n_samples=val.n_samples, scheme="estimation/validation")


def cross_validate(model: HysteresisModel, data: HysteresisData, *, folds: int = FOLDS,
                   max_samples: int = MAX_CV_SAMPLES, n_boot: int = 400, seed: int = 0) -> HeldOut:
    """Refit ``model``'s structure on rolling-origin folds of ``data``; held-out and in-sample error.

    Parameters
    ----------
    model : HysteresisModel
        Gives the base, its settings, fixed parameters and effects (its fitted values are not used).
    data : HysteresisData
        The record (commands and measured angles in deg).
    folds : int
        Held-out blocks.
    max_samples : int
        Longer records are decimated to at most this many samples, as ``validate``'s scan does.
    n_boot, seed : int
        Bootstrap of the held-out metrics' intervals.

    Returns
    -------
    HeldOut

    Raises
    ------
    ModelError
        The record is too short for the folds, or the structure cannot be fitted on a fold.
    """
    stride = max(1, math.ceil(data.n_samples / max_samples))
    d = data.decimate(stride) if stride > 1 else data
    check_cv_data(d, folds)
    bounds = fold_bounds(d.n_samples, folds)
    with one_blas_thread():
        err, fitted = heldout_errors(model, effect_labels(model), d, bounds)
    trains = [fold_split(d, bd)[0] for bd in bounds]
    train_sq = [np.square(predict_extrapolated(m, tr)[0] - tr.meas_deg) for m, tr in zip(fitted, trains)]
    meas = d.meas_deg[bounds[0][0]:bounds[-1][1]]
    return HeldOut(metrics=error_metrics(meas, meas + err, n_boot=n_boot, seed=seed),
                   train_rmse_deg=float(np.sqrt(np.mean(np.concatenate(train_sq)))), errors_deg=err,
                   folds=folds, stride=stride, n_samples=d.n_samples)


def _order(models: list[ModelEntry]) -> list[ModelEntry]:
    """Models of one base together (bases in the order first given), fewer effects first."""
    bases = list(dict.fromkeys(m.base for m in models))
    given = {m.label: i for i, m in enumerate(models)}
    return sorted(models, key=lambda m: (bases.index(m.base), len(m.effects), given[m.label]))


def ladder_size(models: list[ModelEntry], groups: list[Group]) -> int:
    """Rungs :func:`model_ladder` will cross-validate (for the progress bar)."""
    names = {m.label for m in models}
    return sum(1 for g in groups for e in g.evaluations if e.model in names)


def _estimation(m: ModelEntry, record, planes) -> tuple[HysteresisData | None, str]:
    """Estimation data for scoring ``m`` on ``record`` (AlignedData), as validate plans it; None: rolling."""
    try:
        plan = plan_estimation(m.model, [record], model_path=m.path, planes_path=planes)
    except EndocalError as exc:
        return None, f"rolling origin: {exc}"
    if plan.train is None:
        return None, plan.reason
    return axis_data(plan.train, m.axis, planes=plan.planes), plan.reason


def model_ladder(models: list[ModelEntry], groups: list[Group], *, folds: int = FOLDS, n_boot: int = 400,
                 seed: int = 0, alpha: float = 0.05,
                 progress: Callable[[str, int, int], None] | None = None,
                 datas: list | None = None, planes=None) -> list[dict]:
    """Steps of the model ladder: per axis and record, each model structure cross-validated.

    Parameters
    ----------
    models : list of ModelEntry
    groups : list of Group
        The evaluated records (:func:`endocal.report.evaluate.evaluate`); a model is laddered on
        the records it was evaluated on.
    folds : int
        Held-out blocks of the rolling-origin cross-validation.
    n_boot, seed : int
        Bootstrap of the held-out intervals.
    alpha : float
        Level of the step tests (after Holm's correction over the steps of one record).
    progress : callable, optional
        ``progress(step, done, total)`` after each rung.
    datas : list of DataEntry, optional
        The records (their loaded tables): with them a rung whose model file names other
        records as its training data is scored by the estimation/validation split; without
        them every rung is cross-validated by rolling origin.
    planes : path, optional
        The report's ``--planes`` (overrides the planes models record, as in validate).

    Returns
    -------
    list of dict
        In ladder order, with ``axis``, ``data``, ``model`` (label), ``step`` (name drawn on the
        axis), ``base``, ``n_effects``; the cross-validation: ``heldout_rmse_deg``,
        ``heldout_ci``, ``train_rmse_deg`` (in-sample, same fold fits), ``folds``, ``stride``,
        ``n_samples``, ``scheme`` and ``scheme_reason``; against the previous step on the same record:
        ``change_pct`` (held-out RMSE), ``p_value`` (one-sided, raw) and ``p_adjusted``
        (Holm), ``significant``; ``heldout_error`` (why it could not be cross-validated, else
        None); and the model file as given: ``file_rmse_deg``, ``file_ci``,
        ``file_fitted_on_record``.
    """
    total = ladder_size(models, groups)
    records = {d.label: d.aligned for d in (datas or [])}
    steps: list[dict] = []
    done = 0
    for axis in dict.fromkeys(m.axis for m in models):
        ms = _order([m for m in models if m.axis == axis])
        names = [m.name for m in ms]
        unique = len(set(names)) == len(names)
        for g in (g for g in groups if g.axis == axis):
            prev: HeldOut | None = None
            rows = []
            for m in ms:
                try:
                    e = g.evaluation(m.label)
                except KeyError:
                    continue
                done += 1
                if progress:
                    progress(f"ladder: {m.label} on {g.data}", done, total)
                cv, why = None, None
                record = records.get(g.data)
                train, reason = (_estimation(m, record, planes) if record is not None
                                 else (None, "rolling origin: the records were not given"))
                try:
                    if train is not None:
                        cv = split_validate(m.model, train, g.hdata, n_boot=n_boot, seed=seed)
                    else:
                        cv = cross_validate(m.model, g.hdata, folds=folds, n_boot=n_boot, seed=seed)
                except EndocalError as exc:
                    why = str(exc)
                ci = e.metrics.ci.get("rmse_deg")
                hci = None if cv is None else cv.metrics.ci.get("rmse_deg")
                row = {
                    "axis": axis, "data": g.data, "model": m.label, "step": m.name if unique else m.label,
                    "base": m.base, "n_effects": len(m.effects),
                    "heldout_rmse_deg": None if cv is None else cv.metrics.rmse_deg,
                    "heldout_ci": None if hci is None else [hci[0], hci[1]],
                    "train_rmse_deg": None if cv is None else cv.train_rmse_deg,
                    "folds": None if cv is None or cv.scheme != "rolling-origin" else folds,
                    "scheme": None if cv is None else cv.scheme, "scheme_reason": reason,
                    "stride": None if cv is None else cv.stride,
                    "n_samples": None if cv is None else cv.n_samples, "heldout_error": why,
                    "change_pct": None, "p_value": None, "p_adjusted": None, "significant": None,
                    "file_rmse_deg": e.metrics.rmse_deg, "file_ci": None if ci is None else [ci[0], ci[1]],
                    "file_fitted_on_record": e.in_sample,
                }
                if prev is not None and cv is not None and prev.scheme == cv.scheme:
                    if prev.metrics.rmse_deg > 0:
                        row["change_pct"] = 100.0 * (cv.metrics.rmse_deg / prev.metrics.rmse_deg - 1.0)
                    if cv.scheme == "estimation/validation":  # validate's units and test, so both agree
                        units = make_units(g.hdata, [prev.errors_deg])
                        row["p_value"] = unit_test(prev.errors_deg, cv.errors_deg, units)
                    else:
                        row["p_value"], _ = paired_test(prev.errors_deg, cv.errors_deg)
                if cv is not None:
                    prev = cv
                rows.append(row)
            tested = [r for r in rows if r["p_value"] is not None]
            for r, q in zip(tested, holm([r["p_value"] for r in tested])):
                r["p_adjusted"] = float(q)
                r["significant"] = bool(q < alpha)
            steps += rows
    return steps
