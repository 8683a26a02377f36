"""Hold a fitted model against measurements: how far off, where, and which effect is missing.

:func:`validate_offline` returns one :class:`ValidationResult`; the terminal summary, the
``--json`` output and the HTML report all render from it (nothing is computed twice).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from endocal.errors import ModelError
from endocal.messages import Message, key_of
from endocal.models import HysteresisData, make_effect
from endocal.models.base import HysteresisModel
from endocal.runs.aligned import AlignedData
from endocal.validation.bases import minor_loops
from endocal.validation.data import axis_data, check_columns, glitch_note, load_candidates, min_cmd_span
from endocal.validation.metrics import ErrorMetrics, error_metrics
from endocal.validation.regimes import RegimeBreakdown, error_by_regime
from endocal.validation.residuals import (ResidualTests, cut_start, residual_tests, unexplained_shape,
                                          unexplained_start)
from endocal.validation.folds import check_cv_data, fold_bounds, heldout_errors
from endocal.validation.parallel import one_blas_thread
from endocal.validation.predict import predict_errors, predict_extrapolated, predict_scored
from endocal.validation.scan import MAX_SCAN_SAMPLES, scan_effects, scan_split, scan_stride, split_errors
from endocal.validation.structure import SCAN_FTOL, effect_labels, fitted_on
from endocal.validation.suspects import ScanResult
from endocal.validation.shift import (RecordShift, covariate_changes, covariates_held, moving_speed_dps,
                                     record_shift)
from endocal.validation.verdict import Pointer, residual_pointers, shift_pointers


@dataclass(frozen=True)
class Comparison:
    """The error of a previous model beside the current one, on the same data.

    Attributes
    ----------
    old_label, new_label : str
        ``base+effect+...`` of each model.
    old_rmse_deg, new_rmse_deg : float
        RMSE of each fitted model on the data (deg).
    old_heldout_rmse_deg, new_heldout_rmse_deg : float
        Held-out RMSE of each model structure under the scan's scheme: refitted on the same
        estimation data and scored on the validation data, or refitted on the same
        rolling-origin folds (deg).
    old_path : str or None
        The previous model's file (None for a model held in memory).
    """

    old_label: str
    new_label: str
    old_rmse_deg: float
    new_rmse_deg: float
    old_heldout_rmse_deg: float
    new_heldout_rmse_deg: float
    old_path: str | None = None

    @property
    def change_pct(self) -> float:
        """Held-out RMSE change from old to new, percent (negative: the error fell)."""
        return 100.0 * (self.new_heldout_rmse_deg / self.old_heldout_rmse_deg - 1.0)

    def to_dict(self) -> dict:
        return {"old_label": self.old_label, "new_label": self.new_label, "old_rmse_deg": self.old_rmse_deg,
                "new_rmse_deg": self.new_rmse_deg, "old_heldout_rmse_deg": self.old_heldout_rmse_deg,
                "new_heldout_rmse_deg": self.new_heldout_rmse_deg, "change_pct": self.change_pct,
                "path": self.old_path}


@dataclass(frozen=True)
class ValidationResult:
    """Everything ``endocal validate`` reports about one model on one data set.

    Attributes
    ----------
    axis : str
        The model's bending axis.
    model : dict
        ``path``, ``base``, ``effects``, ``label``, ``equation``, ``drive_unit`` (the command's: deg, or mm for
        a linear drive), ``fit_warnings``.
    data : list of dict
        ``source``, ``sha256``, ``n_samples`` per table.
    metrics : ErrorMetrics
        The fitted model's error on the data (deg), with block-bootstrap intervals.
    regimes : RegimeBreakdown
        The error by regime of the motion.
    residuals : ResidualTests
        Whiteness and cross-correlation tests.
    scan : ScanResult
        The effects tested on held-out data; ``scan.suspects`` is what is missing.
    notes : tuple of str
        Everything the user should know in words (samples beyond the fitted range, ambiguities,
        effects the data cannot reveal).
    compare : Comparison or None
        A previous model's error beside this one.
    pointers : tuple of Pointer
        Effects the residuals point at that the scan could not test or did not confirm, and a
        condition that changed between the records (:mod:`endocal.validation.verdict`).
    estimation : list of dict
        ``source``, ``sha256``, ``n_samples`` of each estimation table (empty under
        rolling-origin cross-validation).
    shift : RecordShift or None
        A zero shift and a friction change fitted on the validation data with the model held
        (:mod:`endocal.validation.shift`; estimation/validation scheme only).
    unexplained : str
        When the record's start leaves its first stretch far worse than the rest
        (:func:`~endocal.validation.residuals.unexplained_start`), or the residual is a shape
        rather than noise (:func:`~endocal.validation.residuals.unexplained_shape`), what it says.
    beyond_samples : int
        Samples whose command lies beyond the model's fitted range (predicted by extrapolation).
    hdata : HysteresisData or None
        The validation data of the axis as scored (not serialised: for figures).
    predicted_deg : (n,) array or None
        The model's prediction of it, what every metric above scores (deg; not serialised).
    request : ValidationRequest or None
        What :func:`validate_records` was asked (the summary's next commands repeat it).
    next : NextOutcome or None
        With ``next_path``: the next experiment written, or why none was
        (:class:`~endocal.validation.next_experiment.NextOutcome`).
    compare_found : bool
        ``compare`` was not named but found: the model this one was refitted from.
    """

    axis: str
    model: dict
    data: list
    metrics: ErrorMetrics
    regimes: RegimeBreakdown
    residuals: ResidualTests
    scan: ScanResult
    notes: tuple[str, ...] = ()
    compare: Comparison | None = None
    pointers: tuple[Pointer, ...] = ()
    estimation: list = ()
    shift: RecordShift | None = None
    unexplained: str = ""
    beyond_samples: int = 0
    hdata: HysteresisData | None = field(default=None, repr=False, compare=False)
    predicted_deg: np.ndarray | None = field(default=None, repr=False, compare=False)
    request: ValidationRequest | None = None
    next: object = None
    compare_found: bool = False

    @property
    def suspects(self):
        return self.scan.suspects

    @property
    def in_sample(self) -> bool:
        """True when the estimation data includes a validated record: every score is then in-sample."""
        own = {d.get("sha256") for d in self.data} - {None, ""}
        return bool(own & {d.get("sha256") for d in self.estimation})

    @property
    def clean(self) -> bool:
        """True when nothing is missing: the scan ran on blocks where the axis moves, found no
        suspect, no candidate that clears the gain bar and no other base to suggest, and the residual
        points at no effect."""
        unsettled = any(s.gain_pct >= self.scan.min_gain_pct for s in self.scan.tested)
        return (not self.suspects and not self.scan.base_suggestions and not self.pointers and not unsettled and self.scan.scheme != "none"
                and not self.scan.still_blocks and not self.unexplained)

    def to_dict(self) -> dict:
        """One JSON-able object: ``metrics``, ``regimes``, ``residuals``, ``suspects``, ``notes`` and more."""
        return {
            "axis": self.axis,
            "model": {**self.model, "fit_warning_keys": [key_of(w) for w in self.model.get("fit_warnings", [])]},
            "data": list(self.data),
            "metrics": self.metrics.to_dict(),
            "heldout_rmse_deg": self.scan.baseline_rmse_heldout_deg,
            "regimes": self.regimes.to_dict(),
            "residuals": self.residuals.to_dict(),
            "suspects": [s.to_dict() for s in self.scan.suspects],
            "scan": self.scan.to_dict(),
            "scheme": {"name": self.scan.scheme, "reason": self.scan.scheme_reason, "in_sample": self.in_sample},
            "estimation": list(self.estimation),
            "pointers": [p.to_dict() for p in self.pointers],
            "shift": None if self.shift is None else self.shift.to_dict(),
            "clean": self.clean,
            "unexplained": self.unexplained,
            "beyond_samples": self.beyond_samples,
            "notes": list(self.notes),
            "note_keys": [key_of(n) for n in self.notes],
            "compare": None if self.compare is None else self.compare.to_dict(),
            **({} if self.next is None else {"next": self.next.to_dict()}),
        }


@dataclass(frozen=True)
class ValidationRequest:
    """What a validation was asked, as the summary's next commands repeat it.

    Attributes
    ----------
    model_path : str or None
        The model's file (None: a model held in memory).
    data : tuple of str
        The validation records.
    train : tuple of str
        Estimation data given explicitly (``--train``).
    cv, probe : str
    planes : str or None
        Planes given explicitly (``--planes``).
    folded : bool
        ``refit_on="all"``: the refits fold the validation data in.
    next_possible : bool
        ``--next`` can design for this model and these records (a knob's axis of the probe, a
        fitted range a motion fits in).
    """

    model_path: str | None
    data: tuple[str, ...]
    train: tuple[str, ...] = ()
    cv: str = "auto"
    planes: str | None = None
    probe: str = "tee"
    folded: bool = False
    next_possible: bool = False


def previous_model_path(model_path: str | Path, effects: Sequence[str], base: str | None = None) -> Path | None:
    """The model ``model_path`` was refitted from, by the naming of the refit command, when that file exists:
    ``M-EFFECT.json`` (``M-EFFECT-all.json`` under ``refit_on="all"``, ``M-EFFECT-insample.json`` from
    estimation data that holds the validated record) from ``M.json``; and a base change's
    ``M-BASE.json`` (``M-BASE-EFFECT.json`` with an effect added beside it, :func:`bases._refit`)
    from ``M.json``, when ``base`` is the model's."""
    model_path = Path(model_path)
    name = model_path.name
    if not name.endswith(".json"):
        return None
    stem = name[:-5].removesuffix("-all").removesuffix("-insample")
    tags = ["-" + e.replace(":", "-") for e in effects]
    for tag in tags:
        if stem.endswith(tag):
            cand = model_path.with_name(stem[: -len(tag)] + ".json")
            if cand.is_file():
                return cand
    if base:  # a base change: -BASE, then the effects added beside it, if any
        rest = stem
        while True:
            if rest.endswith("-" + base) and (cand := model_path.with_name(rest[: -len(base) - 1] + ".json")).is_file():
                return cand
            tag = next((t for t in tags if rest.endswith(t)), None)
            if tag is None:
                return None
            rest = rest[: -len(tag)]
    return None


def validate_records(model: HysteresisModel, tables: Sequence[AlignedData], *, model_path: str | Path | None = None,
                     train_paths: Sequence[str | Path] = (), cv: str = "auto", planes_path: str | Path | None = None,
                     compare: HysteresisModel | None = None, compare_path: str | Path | None = None,
                     find_previous: bool = True, refit_on: str = "estimation", folds: int = 5, seed: int = 0,
                     load_columns: Sequence[str] | None = None, next_path: str | Path | None = None,
                     probe: str | Path = "tee") -> ValidationResult:
    """``endocal validate MODEL DATA...`` offline, and :func:`endocal.api.validate`: the one pipeline both call.

    Decides the estimation data (:func:`~endocal.validation.estimation.plan_estimation`), finds the model
    to compare with, validates (:func:`validate_offline`) and, with ``next_path``, writes the next
    experiment (:func:`~endocal.validation.next_experiment.write_next`). Every view (the terminal
    summary, ``--explain``, ``--json``, the API's objects) renders the result it returns.

    Parameters
    ----------
    model : HysteresisModel
    tables : sequence of AlignedData
        The validation records, loaded.
    model_path : path, optional
        The model's file: recorded estimation data and planes are looked up beside it, refits start
        from it and are named after it.
    train_paths : sequence of path
        Estimation data given explicitly (default: the records the model file names).
    cv : {"auto", "rolling", "split"}
    planes_path : path, optional
        Overrides the bending planes the model was fitted through.
    compare, compare_path : optional
        A previous model (and its file) to show beside this one.
    find_previous : bool
        Without ``compare``: compare with the model this one was refitted from, found by the refit
        command's naming (:func:`previous_model_path`).
    refit_on : {"estimation", "all"}
        What the suggestions' refits fit on.
    folds, seed, load_columns
        As :func:`validate_offline`.
    next_path : path, optional
        Write the next experiment there.
    probe : str or path
        The probe the next experiment is for when the records name none.

    Raises
    ------
    ModelError
        Bad ``folds`` or ``refit_on``, a ``compare`` model of another axis, and what
        :func:`validate_offline`, ``plan_estimation`` and (with ``next_path``) ``check_next`` raise.
    """
    from endocal.errors import EndocalError
    from endocal.models import load_model
    from endocal.validation.estimation import plan_estimation
    from endocal.validation.next_experiment import check_next

    if folds < 2:
        raise ModelError(f"folds must be 2 or more (held-out blocks of the rolling-origin scan), got {folds}")
    if refit_on not in ("estimation", "all"):
        raise ModelError(f"refit_on must be 'estimation' or 'all', got {refit_on!r}")
    try:  # a fitted range no motion fits in: with next_path refused before the validation
        check_next(model, tables, probe)
        next_possible = True
    except EndocalError:
        if next_path is not None:
            raise
        next_possible = False
    plan = plan_estimation(model, tables, model_path=model_path, train_paths=list(train_paths), cv=cv,
                           planes_path=planes_path)
    found = False
    if compare is None and find_previous and model_path is not None:
        compare_path = previous_model_path(model_path, effect_labels(model), model.base_name)
        if compare_path is not None:  # found by its name only: one that does not load or fits another axis is no previous model
            try:
                compare = load_model(compare_path)
            except EndocalError:
                compare = None
            found = compare is not None and compare.axis == model.axis
            if not found:
                compare, compare_path = None, None
    if compare is not None and compare.axis != model.axis:
        raise ModelError(f"compare {compare_path or 'model'} is a model of axis '{compare.axis}', but "
                         f"{model_path or 'this model'} is of axis '{model.axis}': compare with a model of the same axis")
    data_paths = [str(a.source) for a in tables]
    refit_paths, suffix = plan.train_paths, ""
    if refit_on == "all" and plan.train is not None:  # asked for: the validation data folded into the refits
        refit_paths, suffix = list(dict.fromkeys([*plan.train_paths, *data_paths])), "-all"
    result = validate_offline(model, tables, train=plan.train, train_paths=refit_paths, planes=plan.planes,
                              planes_path=plan.planes_path, scheme_reason=plan.reason, folds=folds, seed=seed,
                              compare=compare, compare_path=None if compare_path is None else str(compare_path),
                              model_path=None if model_path is None else str(model_path), data_paths=data_paths,
                              load_columns=load_columns, refit_suffix=suffix)
    outcome = None
    if next_path is not None:
        from endocal.validation.next_experiment import write_next

        outcome = write_next(model, result, tables, plan.train, plan.planes, next_path, probe=probe,
                             model_path=model_path)
    request = ValidationRequest(model_path=None if model_path is None else str(model_path), data=tuple(data_paths),
                                train=tuple(map(str, train_paths)), cv=cv,
                                planes=None if planes_path is None else str(planes_path), probe=str(probe),
                                folded=bool(suffix), next_possible=next_possible)
    return replace(result, request=request, next=outcome, compare_found=found)


def model_label(model: HysteresisModel) -> str:
    """``base+effect+...`` (what the ladder of models calls each rung)."""
    return "+".join([model.base_name] + effect_labels(model))


def _resolve_axis(model: HysteresisModel, datas: list[AlignedData], what: str = "validation data") -> str:
    axes = [set(a.axes) for a in datas]
    common = set.intersection(*axes)
    if model.axis is not None:
        for a in datas:
            if model.axis not in a.axes:
                raise ModelError(f"the model is for axis '{model.axis}' but {a.source} ({what}) has axis "
                                 f"{', '.join(a.axes)}; give {what} of axis '{model.axis}'")
        return model.axis
    if len(common) == 1:
        return next(iter(common))
    raise ModelError(f"the model names no axis and the data has several ({', '.join(sorted(common))}); "
                     "refit the model with --axis")


def _axis_of(datas, model: HysteresisModel, axis: str | None, planes, bending_axes, what: str = "validation data"):
    """(HysteresisData, axis, per-table info, bending axes, paths, glitches left out) of loaded tables or one
    HysteresisData."""
    if isinstance(datas, HysteresisData):
        ax = axis or model.axis or "axis"
        return (datas, ax, [{"source": None, "sha256": None, "n_samples": datas.n_samples}], list(bending_axes or []),
                None, "")
    tables = [datas] if isinstance(datas, AlignedData) else list(datas)
    if not tables:
        raise ModelError("no data given: name at least one run folder or aligned table")
    ax = _resolve_axis(model, tables, what)
    dropped: list = []
    data = axis_data(tables, ax, planes, dropped)
    model.check_drive_unit(data, f"{', '.join(str(a.source) for a in tables)} ({what})")
    info = [{"source": str(a.source), "sha256": a.sha256, "n_samples": a.n_rows,
             "duration_s": float(np.ptp(a.t_s))} for a in tables]
    for src, n_cmd, n_meas, n_held, t0 in dropped:
        entry = next(d for d in info if d["source"] == src)
        entry["glitches_left_out"] = {"command": n_cmd, "measured": n_meas, "held": n_held, "first_t_s": t0}
    axes_all = list(bending_axes) if bending_axes is not None else sorted(set().union(*(a.axes for a in tables)))
    return data, ax, info, axes_all, [str(a.source) for a in tables], glitch_note(dropped, ax)


def _no_scan(reason: str, alpha: float, min_gain_pct: float) -> ScanResult:
    return ScanResult((), (), float("nan"), {}, (), 0, 1, 0, alpha, min_gain_pct, scheme="none",
                      scheme_reason=reason)


def slow_clock(n_samples: int, span_s: float) -> str:
    """A ``slow-clock`` warning when records of ``n_samples`` over ``span_s`` hold under one sample per second,
    else ``""`` (``fit`` says it too).

    Knob loops are logged at tens of Hz or more; a clock in ms written as ``t_s`` reads 1000x too
    slow and would make every time-based effect (delay, creep, drift) meaningless.
    """
    from endocal.runs.format import LOG_RATE_RANGE_HZ

    rate = n_samples / span_s if span_s > 0 else 0.0
    if not 0 < rate < LOG_RATE_RANGE_HZ[0]:
        return ""
    return Message(f"{rate:.3g} samples per second: is t_s in seconds? (a clock in ms reads 1000x too slow; endocal "
                   "import csv converts units)", "slow-clock")


#: Fewest validation samples: the whiteness test (Ljung-Box) needs a lag-1 autocorrelation of the
#: residual over a few samples (a record of one back-and-forth sweep has hundreds).
MIN_VALIDATION_SAMPLES = 4


def validate_offline(model: HysteresisModel, datas, *, train=None, axis: str | None = None, folds: int = 5,
                     seed: int = 0, alpha: float = 0.05, min_gain_pct: float = 10.0,
                     compare: HysteresisModel | None = None, compare_path: str | None = None,
                     model_path: str | None = None,
                     data_paths: Sequence[str] | None = None, train_paths: Sequence[str] | None = None,
                     planes=None, planes_path: str | None = None, scheme_reason: str | None = None,
                     load_columns: Sequence[str] | None = None, bending_axes: Sequence[str] | None = None,
                     max_scan_samples: int = MAX_SCAN_SAMPLES, n_boot: int = 400,
                     refit_suffix: str = "") -> ValidationResult:
    """Validate a fitted model on measured data: metrics, regimes, residual tests, missing effects.

    Two schemes test the candidate effects (:mod:`endocal.validation.scan`):

    estimation/validation (``train`` given)
        the model's structure and each augmented structure are fitted on the estimation
        data ``train`` and scored on the validation data ``datas``, unit by unit
        (:func:`~endocal.validation.scan.scan_split`): the split every
        system-identification tool works with, and the one that suits short records (one
        sweep to fit, one to validate);
    rolling origin (no ``train``)
        blocked cross-validation on ``datas`` alone
        (:func:`~endocal.validation.scan.scan_effects`); data too short for it gets the
        metrics, regimes and residual tests, and a note instead of a scan.

    Parameters
    ----------
    model : HysteresisModel
        A fitted model (:func:`endocal.models.load_model`).
    datas : AlignedData, list of AlignedData, or HysteresisData
        Validation data: run folders / aligned tables (loaded), or one axis's data directly.
    train : AlignedData, list of AlignedData, or HysteresisData, optional
        Estimation data (what the model was, or is to be, fitted on).
    axis : str, optional
        Axis of ``HysteresisData`` input (default: the model's).
    folds : int
        Held-out blocks of the rolling-origin scan.
    seed : int
        Seed of the bootstrap intervals.
    alpha, min_gain_pct : float
        Significance level (Holm) and smallest held-out gain of a suspect.
    compare : HysteresisModel, optional
        A previous model: its error is shown beside this one's, under the same scheme.
    compare_path : str, optional
        Its file, recorded in the comparison.
    model_path : str, optional
        Where the model came from (the suspects' refits start from it and name their output after it).
    data_paths, train_paths : sequence of str, optional
        Validation and estimation data paths. The suspects' refits fit on ``train_paths``
        under the estimation/validation scheme (the validation data is not folded in),
        on ``data_paths`` under rolling origin.
    planes : PlanesCalibration, optional
        The bending planes the model was fitted through: measured angles of both data sets
        are mapped into the twisted planes first, as ``fit hysteresis --planes`` did.
    planes_path : str, optional
        The file of ``planes``, for the suspects' refits.
    scheme_reason : str, optional
        Why this scheme runs (recorded and printed).
    load_columns : sequence of str, optional
        Columns to try ``load`` on (default: every varying extra column but the knob drives').
    bending_axes : sequence of str, optional
        The probe's bending axes (default: the data's axes).
    max_scan_samples : int
        Decimate longer records for the scan (see :func:`~endocal.validation.scan.scan_effects`).
    n_boot : int
        Bootstrap replicates of the metrics' intervals.
    refit_suffix : str
        Ends the refits' file names (``-all`` when ``train_paths`` hold the validation data).

    Returns
    -------
    ValidationResult

    Raises
    ------
    ModelError
        Unfitted model, a model for an axis the data lacks or commands in another unit (a knob's
        deg, a linear drive's mm), ``load:`` on a missing or constant column, estimation data no
        model can be fitted on.
    """
    model._require_fitted()
    data, ax, info, axes_all, val_paths, val_glitches = _axis_of(datas, model, axis, planes, bending_axes)
    if data.meas_deg is None:
        raise ModelError("validation needs measured angles")
    if data.n_samples < MIN_VALIDATION_SAMPLES:
        where = ", ".join(map(str, val_paths or data_paths or ["the validation data"]))
        raise ModelError(f"{where}: {data.n_samples} sample(s) of axis {ax}; validation needs at least "
                         f"{MIN_VALIDATION_SAMPLES} (the residual's autocorrelation is tested at lag 1 and more): "
                         "validate on a record of the knob moving, e.g. one back-and-forth sweep")
    span = float(np.ptp(data.cmd_deg))
    if span < min_cmd_span(data):
        where = ", ".join(map(str, val_paths or data_paths or ["the validation data"]))
        raise ModelError(f"{where}: the {ax} command spans only {span:.2f} {data.cmd_unit}: the record does not excite "
                         f"this axis, so there is no hysteresis to judge; validate on a record that moves the {ax} "
                         "knob")
    paths = list(data_paths) if data_paths is not None else (val_paths or ["DATA"])
    est, est_info = None, []
    if train is not None:
        est, _, est_info, est_axes, est_paths, est_glitches = _axis_of(train, model, ax, planes, bending_axes,
                                                                     "estimation data")
        axes_all = sorted(set(axes_all) | set(est_axes))
        if train_paths is None:
            train_paths = est_paths or ["TRAIN"]
    labels = effect_labels(model)
    # load:COLUMN is fitted where the scan fits (the estimation data, else these data): the column must
    # vary there; the validation data only need it (a record at one sheath curvature is valid data)
    own = [e.column for e in map(make_effect, labels) if e.name == "load"] + list(load_columns or [])
    check_columns(data, own, vary=est is None)
    if est is not None:
        check_columns(est, own, what="the estimation data")

    pred, beyond, starts = predict_scored(model, data)
    own: dict = {}

    def score_own() -> None:
        """The model's own scores, worked out in this process while the scan's candidates fit on the other cores."""
        load_cols = list(dict.fromkeys([*(load_columns or []), *load_candidates(data, axes_all)[0]]))
        own.update(metrics=error_metrics(data.meas_deg, pred, n_boot=n_boot, seed=seed),
                   regimes=error_by_regime(data, pred, seed=seed),
                   resid=residual_tests(data, data.meas_deg - pred, alpha=alpha, load_columns=load_cols),
                   loops=minor_loops(model, data, data.meas_deg - pred))

    in_sample = []
    if est is not None:
        same = {d["sha256"] for d in est_info if d["sha256"]} & {d["sha256"] for d in info if d["sha256"]}
        if same:
            in_sample.append(Message("the estimation data includes the record validated here: the scores are "
                                     "in-sample and flatter the model; validate on a record the model was not fitted "
                                     "on", "in-sample"))
            # the refit is fitted on the validated record too: not under the name a refit on
            # estimation data alone would take (that model, if made, is the one to keep)
            refit_suffix = refit_suffix or "-insample"
        scan = scan_split(model, est, data, alpha=alpha, min_gain_pct=min_gain_pct, load_columns=load_columns,
                          bending_axes=axes_all, max_samples=max_scan_samples, data_paths=list(train_paths),
                          model_path=model_path, planes_path=planes_path,
                          scheme_reason=scheme_reason or "estimation data given", refit_suffix=refit_suffix,
                          meanwhile=score_own)
    else:
        reason = scheme_reason or "no separate estimation data"
        try:
            check_cv_data(data.decimate(scan_stride(data, max_scan_samples)), folds)
        except ModelError as exc:
            instead = ("validate the model on a record it was not fitted on" if fitted_on(model, data) else
                       "give the record the model was fitted on with --train to test effects on this one as a whole")
            scan = _no_scan(f"{reason}, and rolling-origin cross-validation cannot run on this record alone "
                            f"({exc}); {instead}", alpha, min_gain_pct)
        else:
            scan = scan_effects(model, data, folds=folds, alpha=alpha, min_gain_pct=min_gain_pct,
                                load_columns=load_columns, bending_axes=axes_all, max_samples=max_scan_samples,
                                data_paths=paths, model_path=model_path, planes_path=planes_path,
                                scheme_reason=reason, meanwhile=score_own)
    if not own:  # no scan ran to work them out meanwhile
        score_own()
    metrics, regimes, resid, loops = own["metrics"], own["regimes"], own["resid"], own["loops"]
    notes = [slow_clock(sum(d["n_samples"] for d in info), sum(d.get("duration_s") or 0.0 for d in info)),
             val_glitches, cut_start(data, data.meas_deg - pred, starts=starts),
             Message(loops.note, "minor-loops") if loops and loops.note else "", *in_sample]
    if beyond:
        lo, hi = model.cmd_range_deg_
        notes.append(Message(f"{beyond} of {data.n_samples} samples command beyond the model's fitted range "
                             f"[{lo:.3g}, {hi:.3g}] "
                             f"{model.drive_unit_}: predicted by continuing the model there (an extrapolation); refit "
                             "on data that covers them", "beyond-range"))
    pointers = residual_pointers(model, data, resid, regimes, scan)
    shift = None
    if scan.scheme == "estimation/validation":
        shift = record_shift(model, data)
        named = {p.effect for p in pointers}
        speeds = (moving_speed_dps(est), moving_speed_dps(data))
        pointers += [p for p in shift_pointers(shift, scan, covariate_changes(est, data), speeds,
                                               covariates_held(est, data, axes_all))
                     if p.effect not in named]
    if est is not None:
        est_pred, _, est_starts = predict_scored(model, est)
        notes += [est_glitches, cut_start(est, est.meas_deg - est_pred, "estimation record", est_starts)]
    notes = [n for n in notes if n] + list(scan.notes)
    comp = None
    if compare is not None and scan.scheme != "none":
        compare.check_drive_unit(data, "the data (the --compare model)")
        old_pred, _ = predict_extrapolated(compare, data)
        stride = scan.stride
        with one_blas_thread():
            if scan.scheme == "estimation/validation":
                old_err = (predict_errors(compare, data) if fitted_on(compare, est) else
                           split_errors(compare, effect_labels(compare), est, data, stride))
            else:
                d = data.decimate(stride) if stride > 1 else data
                old_err, _ = heldout_errors(compare, effect_labels(compare), d, fold_bounds(d.n_samples, folds),
                                            SCAN_FTOL)  # as the scan's folds, its baseline
        comp = Comparison(
            old_label=model_label(compare), new_label=model_label(model),
            old_rmse_deg=float(np.sqrt(np.mean((old_pred - data.meas_deg) ** 2))), new_rmse_deg=metrics.rmse_deg,
            old_heldout_rmse_deg=float(np.sqrt(np.mean(old_err**2))),
            new_heldout_rmse_deg=scan.baseline_rmse_heldout_deg,
            old_path=None if compare_path is None else str(compare_path))
    rep = getattr(model, "fit_report_", None)
    fit_warnings = list(rep.warnings) if rep is not None else []
    if rep is not None and rep.status <= 0:  # said by `fit`, and again here: the scores are of unfinished values
        fit_warnings.insert(0, Message(
            f"the model's fit stopped before converging ({rep.message}), refit it from its own values with "
            f"--start-from {model_path or 'the model'}: its parameters may not be final", "not-converged"))
    model_info = {"path": model_path, "base": model.base_name, "effects": labels, "label": model_label(model),
                  "equation": model.equation(), "drive_unit": model.drive_unit_, "fit_warnings": fit_warnings}
    return ValidationResult(axis=ax, model=model_info, data=info, metrics=metrics, regimes=regimes,
                            residuals=resid, scan=scan, notes=tuple(notes), compare=comp, pointers=tuple(pointers),
                            estimation=est_info, shift=shift,
                            unexplained="; and ".join(x for x in (
                                "" if starts else unexplained_start(data, data.meas_deg - pred),
                                unexplained_shape(data, resid)) if x),
                            beyond_samples=beyond, hdata=data, predicted_deg=pred)
