"""Is the base right: the other bases of the catalogue scored as candidates, and the minor-loop statistic.

An effect term cannot repair a base whose memory rule is not the plant's: ``linear``, ``bspline``
and ``pi`` return to the branch they left after a small reversal inside the loop (return-point
memory, as a bank of plays does); ``bouc-wen`` and ``dahl`` do not. So the scan also tries every
other base of :data:`endocal.models.registry.BASES` with the model's own effects, fitted and scored
exactly as an effect candidate is (:mod:`endocal.validation.scan`):

- estimation/validation: fitted on the (decimated) estimation data, scored on the validation data,
  unit by unit (:func:`~endocal.validation.paired.unit_test`);
- rolling origin: refitted fold by fold (:func:`~endocal.validation.folds.fold_errors`), the first
  fold screening as it does for effects, Wilcoxon on block means
  (:func:`~endocal.validation.paired.paired_test`).

The p-values of the base candidates are Holm-corrected among themselves (a family of their own:
a base change is a different question from a missing term, and adding them to the effects' family
would make every effect harder to find). A base is *suggested* when its corrected p-value is below
``alpha`` and it lowers the held-out RMSE by at least ``min_gain_pct`` -- the effects' bars -- and
its refit (``--model BASE`` with the model's effects) is printed; a base of the other memory rule only
where the validation data hold small reversals inside the loop, where the rules differ
(:func:`memory_veto`). Where the minor-loop statistic
(below) points at the base and no base alone is suggested, the bases of the other memory rule are
also tried with the effect candidates that gained most (:func:`joint_changes`), in the same family.

:func:`minor_loops` measures where the error sits: on the samples after a small reversal inside
the loop (a half-cycle shorter than ``MINOR_FRAC`` of the record's span, and the leg that returns from it),
against the rest. A model whose base has return-point memory and whose error there is at least
``MINOR_RATIO`` times the rest's gets a note: its memory rule misses the plant's minor loops.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from endocal.errors import ModelError
from endocal.models import HysteresisData
from endocal.models.base import HysteresisModel
from endocal.models.registry import BASES, make_model
from endocal.validation.folds import fold_errors
from endocal.validation.paired import holm, paired_test, unit_test
from endocal.validation.parallel import map_jobs
from endocal.validation.predict import predict_errors
from endocal.validation.refit import Refit, refit_path
from endocal.validation.regimes import turning_points
from endocal.validation.structure import SCAN_FTOL, effect_labels
from endocal.validation.units import Units

#: Effect candidates a base change is tried together with (:func:`joint_changes`), the best first.
JOINT_EFFECTS = 2
#: A half-cycle shorter than this share of its record's span is a small reversal inside the loop.
MINOR_FRAC = 0.4
#: The minor-loop note needs at least this many small reversals ...
MINOR_MIN_LOOPS = 3
#: ... and the error after them at least this many times the rest's (RMSE ratio). On the random validation
#: run of the closed-loop tests (60 deg, 18 small reversals, 63 % of its samples), `bspline` + `delay` and
#: `pi` + `delay` fitted on the damped sine and the chirp reach 1.0 and 1.1 on the capstan plant (return-point
#: memory: their rule is the plant's), 1.46 and 1.72 on the Bouc-Wen plant (the records of
#: tests/test_validation_closed_loop_bases.py; a bank of plays and its `pi`: tests/test_validation_bases.py).
MINOR_RATIO = 1.3


@dataclass(frozen=True)
class BaseCandidate:
    """Another base, with the model's effects, tested as a candidate.

    Attributes
    ----------
    base : str
        The base's registry name (``bouc-wen``, ``pi``, ...).
    gain_pct : float
        Held-out RMSE improvement over the model as it stands, percent (negative: worse).
    p_value, p_raw : float
        Holm-corrected (among the base candidates) and raw one-sided p-values.
    rmse_heldout_deg, base_rmse_heldout_deg : float
        Held-out RMSE with this base and with the model's (deg).
    significant : bool
        ``p_value < alpha`` and ``gain_pct >= min_gain_pct``: suggested.
    return_point_memory : bool
        Whether this base returns to the branch it left after a small reversal inside the loop.
    refit : Refit
        ``endocal fit hysteresis ... --model BASE --effects (the model's)``.
    evidence : str
        ``significant``, or why not (the p-value, the gain bar, or a fit that failed).
    screened : bool
        Rolling origin: not refitted beyond the first fold (its training fit gained too little).
    added : tuple of str
        Effects the base change brings with it (:func:`joint_changes`); empty for the base with the
        model's effects alone.
    """

    base: str
    gain_pct: float
    p_value: float
    p_raw: float
    rmse_heldout_deg: float
    base_rmse_heldout_deg: float
    significant: bool
    return_point_memory: bool
    refit: Refit
    evidence: str = ""
    screened: bool = False
    added: tuple[str, ...] = ()

    @property
    def name(self) -> str:
        """``bouc-wen``, or ``bouc-wen with deadzone:tip`` for a change that brings an effect."""
        return self.base + (f" with {', '.join(self.added)}" if self.added else "")

    def line(self, what: str = "validation") -> str:
        """``base: bouc-wen lowers the validation RMSE by 55 %, p = 0.001 (1.28 -> 0.58 deg)``."""
        if not np.isfinite(self.gain_pct):
            return f"base: {self.name}: {self.evidence}"
        verb = f"lowers the {what} RMSE by {self.gain_pct:.0f} %" if self.gain_pct >= 0 else \
            f"raises the {what} RMSE by {-self.gain_pct:.0f} %"
        return (f"base: {self.name} {verb}, p = {self.p_value:.2g} ({self.base_rmse_heldout_deg:.3g} -> "
                f"{self.rmse_heldout_deg:.3g} deg)") + self.refit.expected_words()

    def to_dict(self) -> dict:
        """JSON-able; a base that could not be fitted has ``null`` gain and RMSE."""
        return {k: (v.to_dict() if k == "refit" else None if isinstance(v, float) and not np.isfinite(v) else v)
                for k in self.__dataclass_fields__ for v in (getattr(self, k),)}


@dataclass(frozen=True)
class MinorLoops:
    """The error after small reversals inside the loop, against the rest.

    Attributes
    ----------
    n_loops : int
        Small reversals inside the loop (half-cycles shorter than ``MINOR_FRAC`` of the span).
    fraction : float
        Share of the samples after them (the small half-cycle and the leg that returns from it).
    rmse_deg, rest_rmse_deg : float
        RMSE there and elsewhere (deg).
    note : str
        What it says about the base (empty when nothing).
    """

    n_loops: int
    fraction: float
    rmse_deg: float
    rest_rmse_deg: float
    note: str = ""

    @property
    def ratio(self) -> float:
        return self.rmse_deg / self.rest_rmse_deg if self.rest_rmse_deg > 0 else float("inf")

    def to_dict(self) -> dict:
        return {"n_loops": self.n_loops, "fraction": self.fraction, "rmse_deg": self.rmse_deg,
                "rest_rmse_deg": self.rest_rmse_deg, "ratio": self.ratio, "note": self.note}


def other_bases(model: HysteresisModel) -> list[str]:
    """Every base of the registry but the model's own."""
    return [b for b in BASES if b != model.base_name]


def _proxy(model: HysteresisModel, base: str) -> HysteresisModel:
    """An unfitted ``base`` with ``model``'s axis and the fixed values of its effects (not of its base)."""
    own = f"{model.base_name}_"
    fixed = {k: v for k, v in (model.fixed or {}).items() if not k.startswith(own)} or None
    return make_model(base, axis=model.axis, fixed=fixed)


def base_fit(model: HysteresisModel, base: str, train: HysteresisData, ftol: float | None = None,
             added: Sequence[str] = ()) -> HysteresisModel:
    """``base`` with ``model``'s effects (and ``added``) fitted on ``train``, its effects starting from ``model``'s
    values (:meth:`~endocal.models.base.HysteresisModel.fit_from`, as the printed refit's ``--start-from``);
    continued beyond its fitted range as validation scores it. ``ftol``: the fit's stopping rule
    (:func:`~endocal.validation.structure.scan_ftol`; None: the fit's own)."""
    proxy = _proxy(model, base)
    m = make_model(base, [*effect_labels(model), *added], axis=model.axis, fixed=proxy.fixed,
                   out_of_range="extrapolate")
    return m.fit_from(model, train, ftol=ftol)


def base_errors(model: HysteresisModel, base: str, train: HysteresisData, val: HysteresisData,
                ftol: float | None = None, added: Sequence[str] = ()) -> np.ndarray:
    """Validation errors ``pred - meas`` (deg) on ``val`` of ``base`` with ``model``'s effects (and ``added``)
    fitted on ``train``."""
    return predict_errors(base_fit(model, base, train, ftol, added), val)


def _refit(model: HysteresisModel, base: str, data_paths: Sequence[str], model_path: str | None,
           planes_path: str | None, suffix: str, added: Sequence[str] = ()) -> Refit:
    return Refit(data_paths=tuple(str(p) for p in data_paths), axis=model.axis, base=base,
                 effects=(*effect_labels(model), *added),
                 out_path=refit_path(model_path, "-".join([base, *added]), suffix),
                 planes_path=None if planes_path is None else str(planes_path),
                 start_from=None if model_path is None else str(model_path))


def _rank(model, rows, err_base: np.ndarray, alpha: float, min_gain_pct: float, data_paths, model_path,
          planes_path, suffix, failed: dict[str, str]) -> tuple[BaseCandidate, ...]:
    """Holm-correct ``rows`` of ``(base, rmse, p_raw, screened, added, veto)`` and make the candidates, best gain
    first (``added``: effects the change brings; ``veto``: why it is not suggested whatever its p-value, or "")."""
    rmse_base = float(np.sqrt(np.mean(err_base**2)))
    adj = holm([r[2] for r in rows]) if rows else np.array([])
    out = []
    for (base, rmse, p, screened, added, veto), pa in zip(rows, adj):
        gain = 100.0 * (1.0 - rmse / rmse_base) if rmse_base > 0 else 0.0
        significant = bool(pa < alpha and gain >= min_gain_pct and not veto)
        evidence = ("significant" if significant else veto if veto and pa < alpha and gain >= min_gain_pct else
                    f"under the {min_gain_pct:g} % bar" if pa < alpha else f"not significant (p = {pa:.2g})")
        out.append(BaseCandidate(base=base, gain_pct=gain, p_value=float(pa), p_raw=float(p), rmse_heldout_deg=rmse,
                                 base_rmse_heldout_deg=rmse_base, significant=significant,
                                 return_point_memory=bool(BASES[base].return_point_memory),
                                 refit=_refit(model, base, data_paths, model_path, planes_path, suffix, added),
                                 evidence=evidence, screened=screened, added=tuple(added)))
    for base, why in failed.items():
        out.append(BaseCandidate(base=base, gain_pct=float("nan"), p_value=1.0, p_raw=1.0,
                                 rmse_heldout_deg=float("nan"), base_rmse_heldout_deg=rmse_base, significant=False,
                                 return_point_memory=bool(BASES[base].return_point_memory),
                                 refit=_refit(model, base, data_paths, model_path, planes_path, suffix),
                                 evidence=f"could not be fitted ({why})"))
    out.sort(key=lambda c: -c.gain_pct if np.isfinite(c.gain_pct) else np.inf)
    return tuple(out)


def scan_bases_split(model: HysteresisModel, train: HysteresisData, val: HysteresisData, err_base: np.ndarray,
                     units: Units, *, alpha: float, min_gain_pct: float, data_paths: Sequence[str],
                     model_path: str | None = None, planes_path: str | None = None, suffix: str = "",
                     jobs: int | None = None, errors: Sequence | None = None, joint: Sequence = (),
                     effect_rmse: dict[str, float] | None = None) -> tuple[BaseCandidate, ...]:
    """Every other base with the model's effects, fitted on ``train`` (the scan's decimated estimation
    data), scored on ``val`` unit by unit against ``err_base`` (the model's validation errors).

    ``errors``: per base of :func:`other_bases`, its :func:`base_errors` (or the ModelError it raised),
    when the caller fitted them among its own jobs (the effect scan fits them beside its candidates,
    so both cores stay busy); else they are fitted here. ``joint``: ``((base, effect), errors)`` of the
    pairs of :func:`joint_changes`, ranked in the same family; each is suggested only if the base and the
    effect each earn their part (``effect_rmse``: the validation RMSE of the model with each effect alone).
    """
    effect_rmse = effect_rmse or {}
    bases = other_bases(model)
    results = errors if errors is not None else map_jobs(lambda b: base_errors(model, b, train, val), bases, jobs)
    rows, failed, alone = [], {}, {}
    for b, err in zip(bases, results):
        if isinstance(err, ModelError):
            failed[b] = str(err)
        else:
            alone[b] = float(np.sqrt(np.mean(err**2)))
            rows.append((b, alone[b], unit_test(err_base, err, units), False, (), memory_veto(model, b, val)))
    for (b, e), err in joint:
        if isinstance(err, ModelError):
            continue  # the base alone says whether it fits; a pair that does not is no candidate
        rmse = float(np.sqrt(np.mean(err**2)))
        rows.append((b, rmse, unit_test(err_base, err, units), False, (e,),
                     _joint_veto(b, e, rmse, alone.get(b), effect_rmse.get(e), min_gain_pct)
                     or memory_veto(model, b, val)))
    return _rank(model, rows, err_base, alpha, min_gain_pct, data_paths, model_path, planes_path, suffix, failed)


def joint_changes(model: HysteresisModel, val: HysteresisData, err_base: np.ndarray, tested: Sequence,
                  bases: Sequence[BaseCandidate], alpha: float, borrowed: Sequence[str] = ()) -> list[tuple[str, str]]:
    """The ``(base, effect)`` pairs to fit where a base change needs an effect beside it.

    A base whose free branch shapes take up a static effect (a B-spline's branches, a dead band) can fit
    the records better than a base with the plant's memory rule but without that effect. Then neither the
    effect alone (the base's shapes held most of it) nor the other base alone (the effect missing) clears
    the bars, and a loop that follows `validate` stays on a base whose memory rule misses the plant. Where
    the minor-loop statistic says so (:func:`minor_loops`: the error after small reversals inside the
    loop) and no base alone is suggested, each base of the other memory rule is tried with each of the
    JOINT_EFFECTS effect candidates that lowered the validation error most (raw p below ``alpha``).

    ``tested``: the effect scan's candidates (:class:`~endocal.validation.suspects.Suspect`); ``borrowed``:
    those whose gain is the other parameters' (never tried).
    """
    if any(b.significant for b in bases):
        return []
    loops = minor_loops(model, val, err_base)
    if loops is None or not loops.note:
        return []
    effects = [s.effect for s in sorted(tested, key=lambda s: -s.gain_pct)
               if s.gain_pct > 0 and s.p_raw < alpha and s.effect not in borrowed][:JOINT_EFFECTS]
    others = [b for b in other_bases(model) if BASES[b].return_point_memory != model.return_point_memory]
    return [(b, e) for b in others for e in effects]


def base_before_effect(change: BaseCandidate | None, first, err_change: np.ndarray | None,
                       err_first: np.ndarray | None, units: Units | None, alpha: float) -> tuple[bool, str]:
    """Whether the base change ``change`` is the next refit rather than the first effect suspect ``first``,
    and a note when the two are close.

    A base change replaces the whole base; an effect adds a term to it. Where the base gains more but the
    paired test of the two refits (``err_change`` against ``err_first`` on ``units``, one comparison: raw
    p below ``alpha``) cannot tell them apart, the smaller change goes first: a base whose free branch
    shapes take up a static effect (a B-spline's, the envelope's stiffening) can edge out the base with the
    plant's memory rule by a point or two, and a loop that follows it turns back to the wrong memory rule.
    Without errors to compare (rolling origin) the larger gain goes first.
    """
    if change is None:
        return False, ""
    if first is None:
        return True, ""
    if change.gain_pct <= first.gain_pct:
        return False, ""
    if err_change is None or err_first is None or units is None:
        return True, ""
    p = unit_test(err_first, err_change, units)
    if p < alpha:
        return True, ""
    return False, (f"base {change.name} ({change.gain_pct:.0f} %) and {first.effect} ({first.gain_pct:.0f} %) lower the "
                   f"validation RMSE about equally ({change.rmse_heldout_deg:.3g} vs {first.rmse_heldout_deg:.3g} deg, "
                   f"p = {p:.2g} that the base change is better): {first.effect}, the smaller change, first")


def _joint_veto(base: str, effect: str, rmse: float, base_alone: float | None, effect_alone: float | None,
                min_gain_pct: float) -> str:
    """Why a base change with ``effect`` is not suggested although it may clear the bars: one of the two
    does the work alone (each must lower the validation RMSE of the other alone by ``min_gain_pct``); "" if
    both earn their part."""
    for alone_name, alone, other in ((f"the {base} base", base_alone, effect),
                                     (effect, effect_alone, f"the {base} base")):
        if alone is None or not alone > 0:
            return f"{alone_name} alone could not be scored"
        own = 100.0 * (1.0 - rmse / alone)
        if own < min_gain_pct:
            return (f"{alone_name} alone scores {alone:.3g} deg against {rmse:.3g} together: {other}'s own share, "
                    f"{own:.0f} %, is under the {min_gain_pct:g} % bar")
    return ""


def memory_veto(model: HysteresisModel, base: str, val: HysteresisData) -> str:
    """Why ``base`` cannot be suggested on ``val`` whatever its gain: a base of the other memory rule than the
    model's, where ``val`` holds fewer than MINOR_MIN_LOOPS small reversals inside the loop; else "".

    Return-point memory decides what the tip does after a small reversal inside the loop, and nothing
    else. On records without such reversals the two rules predict alike, and a base of the other rule
    gains only by its branch shapes (a B-spline's free curves take up a dead band or a stiffening): on a
    Bouc-Wen plant, a loop that had changed to `bouc-wen` on a random run turned back to `bspline` (-19 %)
    on a sheath-wrap record `--next` asked for, which holds none.
    """
    if BASES[base].return_point_memory == model.return_point_memory:
        return ""
    _, n = minor_loop_mask(val)
    if n >= MINOR_MIN_LOOPS:
        return ""
    rule = "with" if BASES[base].return_point_memory else "without"
    return (f"a change of memory rule (to a base {rule} return-point memory) that the validation data cannot judge: "
            f"they hold {n} small reversal(s) inside the loop, where the rules differ ({MINOR_MIN_LOOPS} needed), so "
            "its gain is its branch shapes'; validate on a record with small reversals (a random run)")


def held_back(model: HysteresisModel, bases: Sequence[BaseCandidate], val: HysteresisData, alpha: float,
              min_gain_pct: float) -> list[str]:
    """The note on the best base that clears both bars but is held back by :func:`memory_veto` (``[]`` if none):
    the summary lists only suggestions, and a lab validating on sweeps alone would not hear of it."""
    for b in bases:
        if not b.significant and b.p_value < alpha and b.gain_pct >= min_gain_pct:
            veto = memory_veto(model, b.base, val)
            if veto:
                return [f"{b.name} lowers the validation RMSE by {b.gain_pct:.0f} % (p = {b.p_value:.2g}) but is not "
                        f"suggested: {veto}"]
    return []


def scan_bases_rolling(model: HysteresisModel, data: HysteresisData, bounds: Sequence[tuple[int, int]],
                       err_base: np.ndarray, base_train_rmse: float, *, alpha: float, min_gain_pct: float,
                       screen_pct: float, data_paths: Sequence[str], model_path: str | None = None,
                       planes_path: str | None = None, jobs: int | None = None) -> tuple[BaseCandidate, ...]:
    """Every other base with the model's effects, refitted fold by fold on ``data`` (the scan's decimated
    record), screened on the first fold's training fit as effects are, then paired-tested on block means."""
    have = effect_labels(model)

    def one(b: str):
        proxy = _proxy(model, b)
        first = fold_errors(proxy, have, data, bounds[0], SCAN_FTOL)
        gain = 100.0 * (1.0 - first[1].fit_report_.rmse_deg / base_train_rmse) if base_train_rmse > 0 else 0.0
        if gain < screen_pct * min_gain_pct:
            e0 = first[0]
            base0 = float(np.sqrt(np.mean(err_base[:e0.size] ** 2)))
            rmse0 = float(np.sqrt(np.mean(e0**2)))
            rmse_base = float(np.sqrt(np.mean(err_base**2)))
            return b, (rmse0 * rmse_base / base0 if base0 > 0 else rmse0), 1.0, True, (), ""
        err = np.concatenate([first[0]] + [fold_errors(proxy, have, data, bd, SCAN_FTOL)[0] for bd in bounds[1:]])
        return b, float(np.sqrt(np.mean(err**2))), paired_test(err_base, err)[0], False, (), memory_veto(model, b, data)

    bases = other_bases(model)
    rows, failed = [], {}
    for b, r in zip(bases, map_jobs(one, bases, jobs)):
        if isinstance(r, ModelError):
            failed[b] = str(r)
        else:
            rows.append(r)
    return _rank(model, rows, err_base, alpha, min_gain_pct, data_paths, model_path, planes_path, "", failed)


def minor_loop_mask(data: HysteresisData, minor_frac: float = MINOR_FRAC) -> tuple[np.ndarray, int]:
    """Samples after a small reversal inside the loop, and how many such reversals.

    A half-cycle (between two turning points, :func:`~endocal.validation.regimes.turning_points`) shorter
    than ``minor_frac`` of its record's span is a small excursion inside the loop; its samples and those
    of the leg that returns from it are marked: there a base with return-point memory goes back onto
    the branch it left, and a plant without it does not.
    """
    mask = np.zeros(data.n_samples, dtype=bool)
    turns = turning_points(data, 0.02)
    n = 0
    for sl in data.run_slices():
        u = data.cmd_deg[sl]
        span = float(np.ptp(u))
        if not span > 0:
            continue
        mine = [int(k) - sl.start for k in turns if sl.start <= k < sl.stop]
        ends = mine[2:] + [u.size]
        for a, b, c in zip(mine, mine[1:], ends):  # half-cycle a -> b between two reversals; the leg b -> c back
            if abs(u[b] - u[a]) < minor_frac * span:
                n += 1
                mask[sl.start + a: sl.start + c] = True
    return mask, n


def minor_loops(model: HysteresisModel, data: HysteresisData, err_deg: np.ndarray) -> MinorLoops | None:
    """The error ``err_deg`` (n,) after small reversals inside the loop against the rest; None without any.

    The note says the base's memory rule misses the plant's minor loops when the base has
    return-point memory, the record holds at least ``MINOR_MIN_LOOPS`` small reversals, and the error
    after them is at least ``MINOR_RATIO`` times the rest's.
    """
    mask, n = minor_loop_mask(data)
    if n == 0 or mask.all() or not mask.any():
        return None
    err = np.asarray(err_deg, dtype=float)
    inside = float(np.sqrt(np.mean(err[mask] ** 2)))
    rest = float(np.sqrt(np.mean(err[~mask] ** 2)))
    ml = MinorLoops(n_loops=n, fraction=float(mask.mean()), rmse_deg=inside, rest_rmse_deg=rest)
    if model.return_point_memory and n >= MINOR_MIN_LOOPS and ml.ratio >= MINOR_RATIO:
        others = [b for b in BASES if not BASES[b].return_point_memory]
        try_ = f"; try a base without it ({', '.join(f'--model {b}' for b in others)})" if others else ""
        note = (f"minor loops: the error after small reversals inside the loop ({n} of them, "
                f"{100 * ml.fraction:.0f} % of samples) is {ml.ratio:.1f}x the rest's ({inside:.3g} vs {rest:.3g} deg): "
                f"the {model.base_name} base's memory rule (return-point memory: a small reversal returns to the "
                f"branch it left) misses the plant's minor loops{try_}")
        ml = MinorLoops(n, ml.fraction, inside, rest, note)
    return ml
