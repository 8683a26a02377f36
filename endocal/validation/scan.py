"""Which physical effect is the model missing: scan the effect catalog on held-out data.

For every effect of :data:`endocal.models.EFFECTS` the model does not have yet (and, for
``load``, every varying extra column; :mod:`endocal.validation.candidates`), the augmented
model ``base + effects + candidate`` is fitted and its error is measured on data it was not
fitted on; the model as it stands is refitted the same way, so both face the same held-out
data. Two schemes make the held-out data:

- :func:`scan_split`: fitted on separate estimation data, scored on the validation data,
  unit by unit (:func:`~endocal.validation.paired.unit_test`);
- :func:`scan_effects`: rolling-origin cross-validation on the validation data alone
  (:mod:`endocal.validation.folds`), block by block
  (:func:`~endocal.validation.paired.paired_test`).

The p-values of all candidates are Holm-corrected. The other bases of the catalogue are scored the
same way, with the model's effects (:mod:`endocal.validation.bases`). A candidate is a *suspect* when its
corrected p-value is below ``alpha`` *and* it cuts the held-out RMSE by at least
``min_gain_pct``: with thousands of samples, statistics alone would flag a term that absorbs
a sliver of a model's structural mismatch; the effect size keeps a model that already
explains the data near its noise floor free of false alarms. Suspects are ranked by held-out
gain; each carries the :class:`~endocal.validation.refit.Refit` that adds it.
"""

from __future__ import annotations

import copy
import math
import re
from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import NamedTuple

import numpy as np

from endocal.errors import EndocalError, ModelError
from endocal.messages import Message
from endocal.models import EFFECTS, HysteresisData
from endocal.models.base import HysteresisModel
from endocal.models.effects import plain_form
from endocal.models.data import half_cycles
from endocal.validation.ambiguity import ambiguities, cautioned_last, demoted, plain_first, settle_lookalikes
from endocal.validation.bases import (base_before_effect, base_errors, held_back, joint_changes, other_bases,
                                     scan_bases_rolling, scan_bases_split)
from endocal.validation.candidates import candidate_effects
from endocal.validation.folds import check_cv_data, fold_bounds, fold_errors, fold_split, still_blocks
from endocal.validation.identifiability import unheld_cautions
from endocal.validation.paired import holm, min_units_for, paired_test, unit_test
from endocal.validation.parallel import map_jobs, one_blas_thread
from endocal.validation.power import estimate_power, evidence_phrase
from endocal.validation.predict import predict_errors
from endocal.validation.refit import suggest_refit
from endocal.validation.regimes import turning_points
from endocal.validation.structure import (SCAN_FTOL, effect_labels, fitted_on, scan_ftol, split_fit, template,
                                         with_candidate)
from endocal.validation.suspects import ScanResult, Suspect
from endocal.validation.units import make_units

#: Longest record the scan fits at full rate (longer ones are decimated to about this many
#: samples): a 600 s record at 100 Hz is scanned at 8 Hz, still >= 25 samples per cycle of
#: the <= 0.3 Hz loops a knob draws, and the budget that keeps the scan of every catalog
#: effect on 60 000 samples under 30 s (bench/bench_scan.py).
MAX_SCAN_SAMPLES = 5000
#: Fewest samples per cycle of a record's fastest motion that a decimated scan keeps, whatever the
#: budget: the budget's own promise above (25 per cycle of a 0.3 Hz loop). A faster record (the
#: rungs of a speed ladder up to a knob's limit, 0.8 Hz) decimated to the budget would keep four
#: samples a cycle, and an effect of speed fitted on them finds none (rate on a ladder to 290 deg/s:
#: -20 % of the ladder's error fitted on every sample, 0 % on one in 30).
MIN_SAMPLES_PER_CYCLE = 25


def _column(candidate: str) -> str | None:
    """The column a candidate names (``load:sheath_wrap_deg``, ``load:friction:sheath_wrap_deg``); None for an effect
    without one (``delay``, ``deadzone:tip``)."""
    arg = candidate.partition(":")[2]
    plain = plain_form(candidate)
    if plain is not None:
        arg = plain.partition(":")[2]
    return arg or None


def scan_stride(data: HysteresisData, max_samples: int = MAX_SCAN_SAMPLES) -> int:
    """The decimation step of a scan: about ``max_samples`` samples, but at least :data:`MIN_SAMPLES_PER_CYCLE`
    per cycle of the data's fastest motion (the 5th percentile of its half-cycles' lengths)."""
    stride = max(1, int(math.ceil(data.n_samples / max_samples)))
    if stride == 1:
        return 1
    half = np.diff(half_cycles(data, 0.05), axis=1).ravel()
    if half.size < 2:
        return stride
    fast = float(np.percentile(half, 5))
    return max(1, min(stride, int(2.0 * fast // MIN_SAMPLES_PER_CYCLE)))


_AT_BOUND = re.compile(r"sits at its (?:lower|upper) bound (\S+):")


class CandidateFit(NamedTuple):
    """One scan candidate, ``base + effects`` fitted on the estimation data (:func:`_split_candidate`)."""

    #: validation errors ``pred - meas`` (deg)
    errors: np.ndarray
    #: the cautions about the effects the model lacks (:attr:`Suspect.caution`)
    cautions: list
    #: the fitted values
    params: dict
    #: the validation errors without the new terms' own share (:func:`_without_own_share`), or None
    without_own: np.ndarray | None
    #: the only cautions say that no record holds what would confirm the effects
    #: (:func:`~endocal.validation.ambiguity.cautioned_last`)
    unconfirmed_only: bool
    #: the fitted values of the new effects whose fit searched a start, as the model prints their names: the
    #: refit starts there (:attr:`~endocal.validation.refit.Refit.start_values`)
    start_values: dict | None = None
    #: the validation RMSE (deg) of the same candidate fitted on the other subsample (:func:`expected_ranges`), when
    #: its job fitted that too (None: the other subsample cannot be fitted); only with ``again_fitted``
    again_rmse_deg: float | None = None
    again_fitted: bool = False


def _split_candidate(model: HysteresisModel, effects: Sequence[str], train: HysteresisData,
                     val: HysteresisData, ftol: float | None = None) -> CandidateFit:
    """``base + effects`` fitted on ``train`` (stopping at ``ftol``: :func:`scan_ftol`) and scored on ``val``."""
    m = split_fit(model, effects, train, ftol=ftol)
    have = set(effect_labels(model))
    new = [e for e in m.effects_ if e.label not in have]
    prefixes = tuple(e.prefix + "_" for e in new)
    cautions = [w for w in m.fit_report_.warnings if prefixes and w.startswith(prefixes)
                and (b := _AT_BOUND.search(w)) and float(b.group(1)) != 0.0]
    cautions += [c for e in new if (c := e.implausible(m.effect_params(e), train))]
    # an effect fitted on records that lack what shows it (creep without a hold) may stand for something else;
    # a caution of that kind alone says nothing against the fitted values (ambiguity.cautioned_last)
    unconfirmed = [c for e in new for c in unheld_cautions(e, train, val)]
    err = predict_errors(m, val)
    return CandidateFit(err, cautions + unconfirmed, dict(m.params_), _without_own_share(m, new, val),
                        bool(unconfirmed) and not cautions, searched_values(m, new))


def searched_values(m: HysteresisModel, new: Sequence) -> dict[str, float]:
    """The fitted free parameters of ``new`` effects of ``m`` that search their start among candidates (a slack, a
    lag: :meth:`~endocal.models.effects.base.Effect.start_candidates`), by the names ``m`` prints.

    A fit on every sample of the estimation data searches again, and can pick another candidate than the scan's
    fit on a subsample did and stop in a worse minimum (a tip-side slack: 0.171 deg training RMSE from its own
    search against 0.158 from the scan's values, on a Bouc-Wen drive's log; scripts/stress_promises.py seed 30).
    """
    labels = m.parameter_labels()
    return {labels[n]: float(m.params_[n]) for e in new if hasattr(e, "start_candidates")
            for n in e.full_names() if n in m.param_names_}


def _without_own_share(m: HysteresisModel, new: list, val: HysteresisData) -> np.ndarray | None:
    """Validation errors of the fitted candidate ``m`` with its new effects set to their :attr:`~Effect.null`
    (everything else as fitted), or None unless every new effect is an additive term that declares one."""
    if not new or any(not (e.null and e.kind == "output") for e in new):
        return None
    off = copy.copy(m)
    off.params_ = {**m.params_, **{f"{e.prefix}_{k}": v for e in new for k, v in e.null.items()}}
    return predict_errors(off, val)


def split_errors(model: HysteresisModel, effects: Sequence[str], train: HysteresisData, val: HysteresisData,
                 stride: int = 1) -> np.ndarray:
    """Validation errors ``pred - meas`` (deg) of ``base + effects`` fitted on ``train`` (every ``stride``-th sample)."""
    return predict_errors(split_fit(model, effects, train, stride, ftol=scan_ftol(stride)), val)


def scan_split(model: HysteresisModel, train: HysteresisData, val: HysteresisData, *, alpha: float = 0.05,
               min_gain_pct: float = 10.0, candidates: Sequence[str] | None = None,
               load_columns: Sequence[str] | None = None, bending_axes: Sequence[str] = (),
               max_samples: int = MAX_SCAN_SAMPLES, data_paths: Sequence[str] = ("DATA",),
               model_path: str | None = None, planes_path: str | None = None,
               scheme_reason: str = "", jobs: int | None = None, refit_suffix: str = "",
               meanwhile: Callable[[], object] | None = None) -> ScanResult:
    """Test every catalog effect the model lacks: fitted on estimation data, scored on validation data.

    The estimation/validation split of system identification (Ljung, *System
    Identification*, 2nd ed., sec. 16.4): the model as it stands and each augmented model
    ``base + effects + candidate`` are fitted on ``train`` and run over every record of
    ``val`` from its start. Their squared errors on ``val`` are compared unit by unit
    (half-cycles, or decorrelation blocks when the command rarely reverses) with a
    sign-flip randomisation test (:func:`unit_test`) and the p-values Holm-corrected. A
    candidate is a suspect when its corrected p-value is below ``alpha`` and it cuts the
    validation RMSE by at least ``min_gain_pct``. Without a suspect, the candidates that clear
    the gain bar are listed as suggestions, their ``evidence`` saying why they are not
    significant: ``"not enough evidence (N units, M needed; ...)"`` when ``val`` holds fewer units
    than any candidate would need to reach ``alpha`` (:func:`min_units_for`), else the p-value;
    either way it says about how many units of this kind would make the candidate significant at
    the gain seen, or that no length will (:mod:`endocal.validation.power`).

    Parameters
    ----------
    model : HysteresisModel
        The model under validation (its structure is refitted on ``train``).
    train, val : HysteresisData
        Estimation and validation data (commands, measured angles, time, extras).
    max_samples : int
        Longer estimation data is decimated to about this many samples for the fits
        (see :func:`scan_effects`); validation data is always scored at full rate.
    data_paths : sequence of str
        The data each suspect's refit fits on (:class:`~endocal.validation.refit.Refit`): the
        estimation data, or with ``refit_suffix`` ``-all`` the validation data folded in.
    model_path : str, optional
        The model's file: each refit starts from it and is named beside it.
    planes_path : str, optional
        The bending planes the model was fitted through, for the refits.
    scheme_reason : str
        Why this scheme runs, recorded in the result.
    jobs : int, optional
        Processes for the fits (:func:`endocal.validation.parallel.n_jobs`).
    refit_suffix : str
        Ends the refit's file name (:func:`~endocal.validation.refit.refit_path`): ``-all`` when
        ``data_paths`` fold the validation data in, so that model does not take the name of the
        one the scan scored.
    meanwhile : callable, optional
        The caller's own work, run in this process while the candidates fit on the other cores
        (:func:`~endocal.validation.parallel.map_jobs`).

    Returns
    -------
    ScanResult
        Scheme ``estimation/validation``: every candidate fitted on ``train``, scored on ``val``.

    Raises
    ------
    ModelError
        The estimation data cannot be fitted (no reversal, too few samples), or the model
        as it stands cannot be refitted on it.
    """
    if train.meas_deg is None or val.meas_deg is None:
        raise ModelError("validation needs the measured angle meas_deg (deg) in estimation and validation data")
    check_fit_data(train, "estimation data")
    stride = scan_stride(train, max_samples)
    dt = train.decimate(stride) if stride > 1 else train
    have = effect_labels(model)
    tested_cands, untestable = candidate_effects(model, dt, candidates, load_columns, bending_axes,
                                                 train=dt, rolling=False)
    # the model as it stands, fitted on this very estimation data, is scored as it is (a refit of
    # the same structure on the same data could only stop elsewhere); else its structure is refitted
    as_is = fitted_on(model, train)
    # the other bases (scored after the effects) are fitted among the same jobs, so both cores stay busy
    bases_fitted = other_bases(model) if candidates is None else []
    structures = ([] if as_is else [have]) + [with_candidate(have, c) for c in tested_cands]
    ftol = scan_ftol(stride)
    # the model as it stands is the yardstick before any candidate is fitted: a candidate that clears the gain bar
    # against it may become a suspect, whose expected range needs it fitted on the other subsample; its job fits that
    # too, on the core that is warm with it, instead of a second round of jobs after the scan
    own = CandidateFit(predict_errors(model, val), [], dict(model.params_), None, False) if as_is else None
    ahead = None if own is None or stride == 1 else (
        other_half(train, stride), float(np.sqrt(np.mean(own.errors**2))) * (1.0 - min_gain_pct / 100.0))

    def job(j):
        if not isinstance(j, list):
            return base_errors(model, j, dt, val, ftol)
        res = _split_candidate(model, j, dt, val, ftol)
        if ahead is not None and float(np.sqrt(np.mean(res.errors**2))) <= ahead[1]:
            res = res._replace(again_rmse_deg=_again_rmse(model, j, ahead[0], val, res.params), again_fitted=True)
        return res

    with one_blas_thread():
        results = map_jobs(job, structures + bases_fitted, jobs, meanwhile)
    results, base_results = results[:len(structures)], results[len(structures):]
    if as_is:
        results = [own] + results
    if isinstance(results[0], ModelError):
        raise ModelError(f"the model as it stands cannot be refitted on the estimation data: {results[0]}") from None
    err_base = results[0].errors  # the model's own: as it stands, or its structure refitted
    fitted, cautions, fitted_params, without_term, unconfirmed, searched = [], {}, {}, {}, set(), {}
    again_known = {}
    for c, res in zip(tested_cands, results[1:]):
        if isinstance(res, ModelError):
            untestable[c] = f"could not be fitted on the estimation data ({res})"
        else:
            if res.again_fitted:
                again_known[c] = res.again_rmse_deg
            fitted.append((c, res.errors))
            cautions[c] = "; ".join(res.cautions)
            fitted_params[c] = res.params
            searched[c] = res.start_values
            if res.unconfirmed_only:
                unconfirmed.add(c)
            if res.without_own is not None:
                without_term[c] = res.without_own
    rmse_base = float(np.sqrt(np.mean(err_base**2)))
    # units sized by the error of the model as it stands: the same for every candidate (a p-value
    # does not depend on which others were tested) and for the report's ladder, which has only the pair
    units = make_units(val, [err_base])
    need = min_units_for(len(fitted), alpha)
    thin = units.n < need
    raw = [unit_test(err_base, e, units) for _, e in fitted]
    adj = holm(raw) if raw else np.array([])
    tested, errs, borrowed = [], {}, {}
    for (c, err), p, pa in zip(fitted, raw, adj):
        cls = EFFECTS[c.partition(":")[0]]
        rmse = float(np.sqrt(np.mean(err**2)))
        gain = 100.0 * (1.0 - rmse / rmse_base) if rmse_base > 0 else 0.0
        significant = bool(pa < alpha and gain >= min_gain_pct)
        if c in without_term and gain >= min_gain_pct:
            # an additive term earns its gain itself: a drift fitted on long records can move the base's zero
            # there and lower a short record's error with its own term near zero (a false discovery)
            rmse_alone = float(np.sqrt(np.mean(without_term[c] ** 2)))
            own_pct = 100.0 * (1.0 - rmse / rmse_alone) if rmse_alone > 0 else 0.0
            if own_pct < min_gain_pct:
                significant = False
                borrowed[c] = Message(
                    f"{c}: its {gain:.0f} % gain comes from the parameters refitted beside it: the same fit without "
                    f"its own term scores {rmse_alone:.3g} deg against {rmse:.3g} (the term's own share {own_pct:.0f} "
                    f"%, under the {min_gain_pct:g} % bar); not suggested", "borrowed")
        # how much more data would settle it, at the gain seen (the power of this very test)
        power = estimate_power(err_base, err, units.bounds, alpha, len(fitted))
        more = evidence_phrase(power, units.kind, gain, min_gain_pct)
        evidence = ("its own term's share is under the bar (the gain is the other parameters')" if c in borrowed else
                    f"not enough evidence ({units.n} units, {need} needed; {more})" if thin else
                    "significant" if significant else
                    f"under the {min_gain_pct:g} % bar (p = {pa:.2g} over {units.n} {units.kind}s)" if pa < alpha else
                    f"not significant (p = {pa:.2g} over {units.n} {units.kind}s; {more})")
        refit = suggest_refit(model, c, data_paths, model_path=model_path, planes_path=planes_path,
                              suffix=refit_suffix, start_values=searched.get(c))
        tested.append(Suspect(effect=c, column=_column(c), gain_pct=gain, p_value=float(pa), p_raw=float(p),
                              rmse_heldout_deg=rmse, base_rmse_heldout_deg=rmse_base, significant=significant,
                              refit=refit, cause=cls.cause, signature=cls.signature, protocol=cls.protocol,
                              n_blocks=units.n, evidence=evidence, caution=cautions[c], power=power))
        errs[c] = err
    tested.sort(key=lambda s: -s.gain_pct)
    # Significant candidates are suspects. Without one, a candidate that still cuts the validation
    # RMSE by the gain bar is listed as a suggestion with its evidence: it was fitted on other data
    # and measured here, so the refit it names lowers this error by that much; the test only says
    # the gain is not consistent enough across units to rule out chance.
    suspects = [s for s in tested if s.significant] or [s for s in tested
                                                        if s.gain_pct >= min_gain_pct and s.effect not in borrowed]
    # a candidate with a caution (a delay at its -0.5 s bound, a drift too fast to be one) ranks after the others,
    # unless it beats the first of them in a paired test; an effect's other form after its plain form where the
    # two explain the residual alike
    suspects, ahead = cautioned_last(suspects, errs, units, alpha, min_gain_pct, unconfirmed)
    suspects = plain_first(suspects, errs, alpha)
    # the first suggestion against the look-alikes it declares, on records that separate them
    # (a look-alike whose gain is borrowed is compared, never promoted)
    suspects, settled = settle_lookalikes(suspects, [s for s in tested if s.effect not in borrowed], errs, dt, val,
                                          units, alpha, min_gain_pct,
                                          lambda effects: _split_candidate(model, effects, dt, val, ftol).errors, have)
    if stride > 1 and suspects:
        ranges = expected_ranges(model, [s.effect for s in suspects], train, val, stride,
                                 [s.rmse_heldout_deg for s in suspects], jobs,
                                 starts=[fitted_params.get(s.effect) for s in suspects], known=again_known)
        suspects = [replace(s, refit=replace(s.refit, scan_stride=stride, expected_rmse_deg=r))
                    for s, r in zip(suspects, ranges)]
        tested = [next((x for x in suspects if x.effect == s.effect), s) for s in tested]
    # ambiguity.py words these notes, one kind per function: each gets its key as it enters the result
    notes = [Message(n, "demoted") for n in demoted(suspects)] + [Message(ahead, "cautioned-first")] * bool(ahead) + (
        [Message(n, "alike") for n in ambiguities(suspects, errs, alpha)] if any(s.significant for s in suspects)
        else [])
    notes += [Message(x.words(), "alike") for x in settled]
    notes += list(borrowed.values())
    notes += [Message(f"{k}: {v}", "untestable") for k, v in untestable.items()]
    if thin and fitted:
        notes.append(Message(f"the validation data holds {units.n} {units.kind}s; with {len(fitted)} candidates at "
                             f"least {need} are needed before any can be significant at {alpha:g}: candidates are "
                             "ranked by their validation gain alone; validate on a longer record (or more records) to "
                             "test them", "few-units"))
    if stride > 1:
        expect = ""
        if suspects and suspects[0].refit.expected_rmse_deg is not None:
            lo, hi = suspects[0].refit.expected_rmse_deg
            expect = (f"; expect {suspects[0].effect}'s refit at {lo:.3g} .. {hi:.3g} deg validation RMSE (the "
                      "candidate fitted on two interleaved subsamples)")
        notes.append(Message(f"candidates fitted on 1 estimation sample in {stride} ({dt.n_samples} of "
                             f"{train.n_samples}) to keep the scan quick; the printed refit fits every sample, so its "
                             f"validation RMSE differs from the candidate's{expect}", "subsampled"))
    bases = () if candidates is not None else scan_bases_split(
        model, dt, val, err_base, units, alpha=alpha, min_gain_pct=min_gain_pct, data_paths=data_paths,
        model_path=model_path, planes_path=planes_path, suffix=refit_suffix, jobs=jobs, errors=base_results)
    pairs = joint_changes(model, val, err_base, tested, bases, alpha, list(borrowed)) if bases else []
    if pairs:  # a base change that needs an effect beside it, ranked in the bases' family
        with one_blas_thread():
            joint = map_jobs(lambda pair: base_errors(model, pair[0], dt, val, ftol, (pair[1],)), pairs, jobs)
        bases = scan_bases_split(
            model, dt, val, err_base, units, alpha=alpha, min_gain_pct=min_gain_pct, data_paths=data_paths,
            model_path=model_path, planes_path=planes_path, suffix=refit_suffix, jobs=jobs, errors=base_results,
            joint=list(zip(pairs, joint)), effect_rmse={s.effect: s.rmse_heldout_deg for s in tested})
    notes += [Message(n, "memory-rule") for n in held_back(model, bases, val, alpha, min_gain_pct)]
    change = next((b for b in bases if b.significant), None)
    if stride > 1 and change is not None:  # the base change's promise too: the range its refit on every sample lands in
        r0 = change.rmse_heldout_deg
        try:
            again = base_errors(model, change.base, other_half(train, stride), val, SCAN_FTOL, change.added)
            expected = spread(r0, float(np.sqrt(np.mean(again**2))))
        except ModelError:  # the other half cannot be fitted: the scanned RMSE alone
            expected = spread(r0, r0)
        bases = tuple(replace(b, refit=replace(b.refit, scan_stride=stride, expected_rmse_deg=expected))
                      if b is change else b for b in bases)
    base_errs = {**{(b, ()): e for b, e in zip(bases_fitted, base_results)},
                 **({(b, (e,)): err for (b, e), err in zip(pairs, joint)} if pairs else {})}
    err_change = None if change is None else base_errs.get((change.base, change.added))
    first = suspects[0] if suspects else None
    base_first, close = base_before_effect(change, first, None if isinstance(err_change, ModelError) else err_change,
                                           None if first is None else errs.get(first.effect), units, alpha)
    if close:
        notes.append(Message(close, "alike"))
    return ScanResult(tuple(suspects), tuple(tested), rmse_base, untestable, tuple(notes), 0, stride,
                      dt.n_samples, alpha, min_gain_pct, scheme="estimation/validation", scheme_reason=scheme_reason,
                      units=units.to_dict(), min_units=need, lookalikes=tuple(settled), bases=bases,
                      base_first=base_first)


def expected_ranges(model: HysteresisModel, effects: Sequence[str], train: HysteresisData, val: HysteresisData,
                    stride: int, rmse_scanned: Sequence[float], jobs: int | None = None,
                    starts: Sequence[dict | None] | None = None,
                    known: dict[str, float | None] | None = None) -> list[tuple[float, float]]:
    """The validation RMSE (deg) to expect of each refit ``base + effects + effect`` on every sample of ``train``,
    when the scan fitted it on 1 sample in ``stride``.

    The scan fitted each candidate on the samples ``0, stride, 2 stride, ...``; this fits it once more on the
    samples halfway between (``stride // 2, ...``) and scores it on ``val``. A refit on every sample sees both
    subsamples, so its RMSE is expected between the two: the range is theirs (``rmse_scanned`` the first), widened
    by half their gap on each side, as two draws pin a spread only roughly. A candidate the second subsample cannot
    fit keeps the scanned RMSE alone.

    ``starts`` (per effect, the candidate's values as the scan fitted them): the second fit starts there, where
    the optimum of the other subsample lies near, instead of searching every start again (several times
    quicker; the same basin the scan scored). ``known``: effect -> the second fit's RMSE (None: it could not be
    fitted), for the effects the scan's own jobs already fitted twice (:func:`_again_rmse`); the others are fitted here.
    """
    dt2 = other_half(train, stride)
    have = effect_labels(model)
    starts = list(starts) if starts is not None else [None] * len(effects)
    known = known or {}
    todo = [k for k, e in enumerate(effects) if e not in known]
    with one_blas_thread():
        again = map_jobs(lambda k: _again_rmse(model, with_candidate(have, effects[k]), dt2, val, starts[k]), todo,
                         jobs)
    rmse = {**known, **{effects[k]: r for k, r in zip(todo, again)}}
    return [spread(r0, r0 if rmse[e] is None else rmse[e]) for r0, e in zip(rmse_scanned, effects)]


def _again_rmse(model: HysteresisModel, effects: list[str], dt2: HysteresisData, val: HysteresisData,
                start: dict | None) -> float | None:
    """The validation RMSE (deg) of ``base + effects`` fitted on the other subsample ``dt2`` (:func:`other_half`),
    from the scan's fitted values ``start`` where there are some; None where ``dt2`` cannot be fitted."""
    try:
        if start:
            err = predict_errors(template(model, effects).fit(dt2, warm_start=start, ftol=SCAN_FTOL), val)
        else:
            err = _split_candidate(model, effects, dt2, val, SCAN_FTOL).errors
    except EndocalError:
        return None
    return float(np.sqrt(np.mean(err**2)))


def other_half(train: HysteresisData, stride: int) -> HysteresisData:
    """The samples halfway between those the scan fitted (``stride // 2, stride // 2 + stride, ...`` of each run)."""
    return train.take([np.arange(sl.start + stride // 2, sl.stop, stride) for sl in train.run_slices()])


def spread(r0: float, r1: float) -> tuple[float, float]:
    """The range between two subsamples' validation RMSEs (deg), widened by half their gap on each side: two
    draws pin a spread only roughly."""
    lo, hi = min(r0, r1), max(r0, r1)
    pad = 0.5 * (hi - lo)
    return max(lo - pad, 0.0), hi + pad


def check_fit_data(data: HysteresisData, what: str = "data") -> None:
    """Refuse data no hysteresis model can be fitted on (no reversal), stating the minimum.

    Raises
    ------
    ModelError
    """
    if turning_points(data).size < 1:
        raise ModelError(f"the {what} never reverses the knob ({data.n_samples} samples): a hysteresis model needs "
                         "at least one reversal (one back-and-forth sweep) to see both branches of the loop")


def scan_effects(model: HysteresisModel, data: HysteresisData, *, folds: int = 5, alpha: float = 0.05,
                 min_gain_pct: float = 10.0, candidates: Sequence[str] | None = None,
                 load_columns: Sequence[str] | None = None, bending_axes: Sequence[str] = (),
                 max_samples: int = MAX_SCAN_SAMPLES, train_frac: float = 0.5, screen_pct: float = 0.5,
                 data_paths: Sequence[str] = ("DATA",), model_path: str | None = None,
                 planes_path: str | None = None, scheme_reason: str = "", jobs: int | None = None,
                 meanwhile: Callable[[], object] | None = None) -> ScanResult:
    """Test every catalog effect the model lacks on held-out data; rank the significant ones.

    Parameters
    ----------
    model : HysteresisModel
        The model under validation (its base, settings and effects are refitted fold by fold).
    data : HysteresisData
        Commands, measured angles, time and extra columns (see :mod:`endocal.validation.data`).
    folds : int
        Held-out blocks (rolling origin, see the module docstring).
    alpha : float
        Family-wise error rate over the candidates (Holm).
    min_gain_pct : float
        Smallest held-out RMSE improvement (percent) worth a model term.
    candidates : sequence of str, optional
        Effects to test (default: every catalog effect the model lacks; ``load`` on every
        varying extra column).
    load_columns : sequence of str, optional
        Columns to try ``load`` on (default: :func:`~endocal.validation.data.load_candidates`).
    bending_axes : sequence of str
        Names of the probe's bending axes (their knob readings are not load candidates).
    max_samples : int
        Longer records are decimated to at most this many samples for the scan (every
        ``s``-th sample). The test's power comes from the number of independent error
        blocks, i.e. from the record's duration over the error's correlation time, not from
        the sample rate; hysteresis loops at <= 1 Hz keep their shape at >= 10 Hz.
    train_frac : float
        Share of the record used only for training.
    screen_pct : float
        A candidate whose fit on the first training block improves that block's RMSE by less
        than ``screen_pct * min_gain_pct`` percent is not refitted on the other folds: a
        nested model gains less on held-out data than on its own training data, so it could
        not reach ``min_gain_pct``. Its p-value is 1 (it still counts in Holm's family) and its
        gain is the first fold's. The decision uses training data only.
    data_paths, model_path : optional
        Where the data and model came from, for the suspects' refits.
    planes_path, scheme_reason, jobs, meanwhile : optional
        As :func:`scan_split` (``meanwhile`` runs while the model's own folds fit).

    Returns
    -------
    ScanResult
        Scheme ``rolling-origin``: every candidate refitted fold by fold on ``data``.

    Raises
    ------
    ModelError
        Data too short for the cross-validation, or the model as it stands cannot be
        refitted on the first training block.
    """
    if data.meas_deg is None:
        raise ModelError("validation needs the measured angle meas_deg (deg)")
    stride = scan_stride(data, max_samples)
    d = data.decimate(stride) if stride > 1 else data
    check_cv_data(d, folds, train_frac)
    bounds = fold_bounds(d.n_samples, folds, train_frac)
    have = effect_labels(model)
    # what the first training block cannot show, no fold can be fitted for
    first_train = fold_split(d, bounds[0])[0]
    tested_cands, untestable = candidate_effects(model, d, candidates, load_columns, bending_axes,
                                                 train=first_train, rolling=True)

    with one_blas_thread():
        base_folds = map_jobs(lambda bd: fold_errors(model, have, d, bd, SCAN_FTOL), bounds, jobs, meanwhile)
        for f in base_folds:
            if isinstance(f, ModelError):
                raise f
        err_base = np.concatenate([e for e, _ in base_folds])
        base_train_rmse = base_folds[0][1].fit_report_.rmse_deg
        rmse_base = float(np.sqrt(np.mean(err_base**2)))

        def candidate(c: str):
            first = fold_errors(model, with_candidate(have, c), d, bounds[0], SCAN_FTOL)
            train_gain = 100.0 * (1.0 - first[1].fit_report_.rmse_deg / base_train_rmse) if base_train_rmse > 0 else 0.0
            if train_gain < screen_pct * min_gain_pct:
                # screened on its training fit alone: no held-out data was looked at to decide
                e0 = first[0]
                rmse0 = float(np.sqrt(np.mean(e0**2)))
                base0 = float(np.sqrt(np.mean(err_base[:e0.size] ** 2)))
                return (c, None, rmse0 * rmse_base / base0 if base0 > 0 else rmse0, 1.0, 0)
            rest = [fold_errors(model, with_candidate(have, c), d, bd, SCAN_FTOL) for bd in bounds[1:]]
            err = np.concatenate([first[0]] + [e for e, _ in rest])
            p, nb = paired_test(err_base, err)
            return (c, err, float(np.sqrt(np.mean(err**2))), p, nb)

        results = []
        for c, r in zip(tested_cands, map_jobs(candidate, tested_cands, jobs)):
            if isinstance(r, ModelError):
                untestable[c] = f"could not be fitted on this data ({r})"
            else:
                results.append(r)

    adj = holm([r[3] for r in results]) if results else np.array([])
    tested = []
    errs = {}
    for (c, err, rmse, p, nb), pa in zip(results, adj):
        cls = EFFECTS[c.partition(":")[0]]
        gain = 100.0 * (1.0 - rmse / rmse_base) if rmse_base > 0 else 0.0
        refit = suggest_refit(model, c, data_paths, model_path=model_path, planes_path=planes_path)
        significant = bool(pa < alpha and gain >= min_gain_pct)
        tested.append(Suspect(effect=c, column=_column(c), gain_pct=gain, p_value=float(pa), p_raw=p,
                              rmse_heldout_deg=rmse, base_rmse_heldout_deg=rmse_base,
                              significant=significant, refit=refit,
                              cause=cls.cause, signature=cls.signature, protocol=cls.protocol, n_blocks=nb,
                              screened=err is None, evidence="significant" if significant else "not significant"))
        if err is not None:
            errs[c] = err
    tested.sort(key=lambda s: -s.gain_pct)
    suspects = plain_first([s for s in tested if s.significant], errs, alpha)
    notes = [Message(n, "alike") for n in ambiguities(suspects, errs, alpha)]
    notes += [Message(f"{k}: {v}", "untestable") for k, v in untestable.items()]
    if stride > 1:
        notes.append(Message(f"scanned 1 sample in {stride} ({d.n_samples} of {data.n_samples})", "subsampled"))
    still = still_blocks(d, bounds)
    if still:
        where = (f"all {folds} held-out blocks hold" if still == folds else f"{still} of the {folds} held-out blocks hold")
        notes.insert(0, Message(f"{where} no motion of this axis (its knob rests while the record goes on): there the "
                                "scan scores only where the model puts the resting bend, not its hysteresis; validate "
                                "on a record where this axis moves throughout", "still-blocks"))
    bases = () if candidates is not None else scan_bases_rolling(
        model, d, bounds, err_base, base_train_rmse, alpha=alpha, min_gain_pct=min_gain_pct, screen_pct=screen_pct,
        data_paths=data_paths, model_path=model_path, planes_path=planes_path, jobs=jobs)
    notes += [Message(n, "memory-rule") for n in held_back(model, bases, d, alpha, min_gain_pct)]
    return ScanResult(tuple(suspects), tuple(tested), rmse_base, untestable, tuple(notes), folds, stride,
                      d.n_samples, alpha, min_gain_pct, scheme="rolling-origin", scheme_reason=scheme_reason,
                      still_blocks=still, bases=bases,
                      base_first=base_before_effect(next((b for b in bases if b.significant), None),
                                                    suspects[0] if suspects else None, None, None, None, alpha)[0])
