"""No verdict that its own residuals contradict: effects the residuals point at but the scan did not confirm.

The effect scan (:mod:`endocal.validation.scan`) can only confirm what it can test: an
effect whose signature the estimation data (or the first training block) lacks is not
fitted, and an effect can be tested and still not pay on the held-out data. The residual
tests and the regimes look at the model's error directly. When they point at an effect the
model lacks and the scan did not confirm, ``validate`` names it as a *pointer*: an untested
or unconfirmed suspect, with the evidence, why the scan could not settle it, and the
experiment that would. ``validate`` says nothing is missing only when there is no suspect
and no pointer.

What points at what (the catalog's signatures, :mod:`endocal.models.effects`):

========================================  ===================
residual correlates with ...              effect
========================================  ===================
the other knob's command                  ``coupling``
time                                      ``drift``
the signed knob speed                     ``delay``, ``rate``
the unsigned knob speed                   ``rate``
a load column times the direction         ``load:COLUMN``
========================================  ===================

and the error of a regime well above the whole record's: the other knob's low or high
band (``coupling``), holds (``creep``). On a record too short for the correlation test (a
cycle or two), a strong correlation at lag 0 points all the same (``MIN_CORR_SHORT``).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

from endocal.models import EFFECTS
from endocal.models.base import HysteresisModel
from endocal.models.data import HysteresisData
from endocal.validation.candidates import takes_column

#: Smallest |cross-correlation| that counts as pointing at an effect. With thousands of
#: samples a correlation of 0.05 is "significant" yet explains 0.25 % of the residual's
#: variance; 0.3 explains about a tenth of it, what the scan's 10 % gain bar asks of a term.
MIN_CORR = 0.3
#: On a record too short for the test to detect MIN_CORR (its bound lies above it: a cycle or
#: two of slow motion, whose residual and signals each hold a handful of independent values),
#: a correlation this strong at lag 0 still points, and says it could not be tested: it
#: accounts for a quarter of the residual's variance, which no verdict of "nothing missing"
#: may ignore.
MIN_CORR_SHORT = 0.5
#: Smallest regime error relative to the whole record's that counts as pointing at an effect.
MIN_RATIO = 1.5

#: What each residual signal is, in words (the signals of :mod:`endocal.validation.residuals`; the
#: effects that a signal points at declare it in ``Effect.residual``).
SIGNAL_WORDS = {
    "other command": "the other knob's command",
    "time": "time",
    "speed": "the signed knob speed",
    "abs speed": "how fast the knob moves",
}


def _alike_words(name: str, alike: list[str]) -> str:
    """Why a term and its look-alikes are not told apart where the records do not separate them."""
    return f"where the records do not separate them, {name} looks like {' or '.join(alike)}"


def declaring(signal: str) -> list[str]:
    """Catalogue effects that declare ``signal`` in ``residual``, in catalogue order."""
    return [name for name, cls in EFFECTS.items() if signal in cls.residual]


def _pointed_at(kind: str) -> dict[str, list[str]]:
    """Signal (or ``regime:NAME``) -> the catalogue effects that declare it in ``residual``, in catalogue order."""
    out: dict[str, list[str]] = {}
    for name, cls in EFFECTS.items():
        for r in cls.residual:
            if isinstance(r, str) and r.startswith("regime:") == (kind == "regime"):
                out.setdefault(r, []).append(name)
    return out


@dataclass(frozen=True)
class Pointer:
    """An effect the residuals point at that the scan did not confirm.

    Attributes
    ----------
    effect : str
        Catalog effect name.
    evidence : str
        What in the residual points at it, in words (correlations, regimes).
    status : {"untested", "unconfirmed"}
        ``untested``: the scan could not fit or test it on this data; ``unconfirmed``: it
        was tested and did not lower the held-out error enough.
    why : str
        Why the scan could not settle it.
    experiment : str
        The experiment or data that would test it.
    """

    effect: str
    evidence: str
    status: str
    why: str
    experiment: str

    def to_dict(self) -> dict:
        return asdict(self)


def _evidence(resid, regimes) -> dict[str, list[str]]:
    out: dict[str, list[str]] = {}
    by_signal = _pointed_at("signal")
    for x in resid.cross:
        if x.significant and x.max_abs_corr >= MIN_CORR:
            r, lag, untested = x.max_abs_corr, x.lag_s, ""
        elif (not x.significant and x.bound >= MIN_CORR and abs(x.corr_at_zero) >= MIN_CORR_SHORT
              and x.signal != "time"):
            # at lag 0 only, where each signature lies: on a cycle or two, the best of all lags
            # lines up any slow residual with any slow signal. Not time: over a cycle or two any
            # residual that differs between the record's start and end follows the clock.
            r, lag = abs(x.corr_at_zero), 0.0
            untested = (", a record too short for any correlation to be significant (too few independent stretches)"
                        if x.bound >= 1.0 else
                        f", not significant on a record this short (that takes |r| above {x.bound:.2g})")
        else:
            continue
        if x.signal.startswith("load:"):
            # a condition column: the effects that declare "load" read it, written NAME:COLUMN
            column = x.signal.partition(":")[2]
            effects, words = ([f"{e}:{column}" for e in by_signal.get("load", [])],
                              f"'{column}' times the direction of motion")
        elif x.signal in by_signal:
            effects, words = by_signal[x.signal], SIGNAL_WORDS.get(x.signal, x.signal)
        else:
            continue
        for e in effects:
            out.setdefault(e, []).append(f"the residual follows {words} (|r| = {r:.2f} at lag {lag:+.3g} s{untested})")
    by_regime = _pointed_at("regime")
    for r in regimes.regimes:
        key = f"regime:{r.group}" if f"regime:{r.group}" in by_regime else (
            "regime:hold" if r.name.startswith("hold") else None)
        if key is None or key not in by_regime or r.ratio < MIN_RATIO:
            continue
        for e in by_regime[key]:
            out.setdefault(e, []).append(
                f"the error in '{r.name}' is {r.ratio:.2f}x the whole record's ({r.metrics.rmse_deg:.3g} deg)")
    for name, cls in EFFECTS.items():  # an effect's own statistic of the residual
        for f in cls.residual:
            if callable(f):
                out.setdefault(name, []).extend(f(resid, regimes) or [])
    return {k: v for k, v in out.items() if v}


def residual_pointers(model: HysteresisModel, data: HysteresisData, resid, regimes, scan) -> list[Pointer]:
    """Effects the residual tests and regimes point at that the model lacks and the scan did not confirm.

    Parameters
    ----------
    model : HysteresisModel
        The model under validation (effects it has are not pointed at).
    data : HysteresisData
        The validation data.
    resid : ResidualTests
        :func:`~endocal.validation.residuals.residual_tests` of the model's residual.
    regimes : RegimeBreakdown
        :func:`~endocal.validation.regimes.error_by_regime` of the model's error.
    scan : ScanResult
        What the effect scan tested and confirmed.

    Returns
    -------
    list of Pointer
        In the order of the table in the module docstring.
    """
    def key(label: str) -> str:  # an effect that needs its column is one term per column (load:COLUMN)
        name = label.partition(":")[0]
        return label if name in EFFECTS and takes_column(name) else name

    have = {key(e.label) for e in model.effects_}
    confirmed = {key(s.effect) for s in scan.suspects}
    tested = {key(s.effect): s for s in scan.tested}
    untestable = {key(k): v for k, v in scan.untestable.items()}
    out = []
    for effect, ev in _evidence(resid, regimes).items():
        name = effect.partition(":")[0]
        if effect in have or effect in confirmed or name not in EFFECTS:
            continue
        experiment = f"record {EFFECTS[name].protocol}"
        if effect in untestable:
            status, why = "untested", untestable[effect]
        elif ":" in effect and name in untestable:
            col = effect.partition(":")[2]
            status, why = "untested", (f"'{col}' varies here but not in the data the candidates are fitted on: "
                                       f"{effect} cannot be fitted there")
        elif scan.scheme == "none":
            status, why = "untested", scan.scheme_reason
        elif effect in tested:
            s = tested[effect]
            status = "unconfirmed"
            why = (f"fitted and tested, it changed the held-out RMSE by {-s.gain_pct:+.0f} % "
                   f"({s.base_rmse_heldout_deg:.3g} -> {s.rmse_heldout_deg:.3g} deg, p = {s.p_value:.2g}): ")
            if s.gain_pct < 0 and scan.scheme == "estimation/validation":
                # a term that makes unseen data worse was fitted to something else in the estimation data
                alike = [other for other in EFFECTS[name].lookalikes if other in EFFECTS]
                why += ("the estimation data does not pin it down"
                        + (f" ({_alike_words(name, alike)})" if alike else "")
                        + ", or the catalog term does not capture what the residual shows here")
                experiment = f"record estimation data with {EFFECTS[name].protocol}"
            else:
                why += ("the catalog term does not capture what the residual shows here, or the held-out data "
                        "does not exercise it")
        else:
            continue
        out.append(Pointer(effect, "; ".join(dict.fromkeys(ev)), status, why, experiment))
    return out


#: A change between the records is named when refitting it on the validation record cuts the
#: error by this fraction (the issue's bar for an effect worth a term, 30 %) and leaves it this
#: far below every catalog effect fitted on the estimation record.
SHIFT_CUT = 0.7
#: A validation record this many times as fast as the estimation record (typical knob speed
#: while moving) can owe a wider loop to speed (a lag, friction growing with speed) rather
#: than to a condition that changed: a lag of 80 ms widens the loop by 0.08 s x the speed.
SPEED_RATIO = 1.5


def shift_pointers(shift, scan, covariates: list[str] = (), speeds_dps: tuple[float, float] | None = None,
                   held: list[str] = ()) -> list[Pointer]:
    """A condition that changed between the estimation and validation records, as a pointer.

    Parameters
    ----------
    shift : RecordShift
        :func:`~endocal.validation.shift.record_shift` of the model on the validation data.
    scan : ScanResult
        The estimation/validation scan (its best candidate is the bar to beat).
    covariates : list of str
        :func:`~endocal.validation.shift.covariate_changes`, in words.
    speeds_dps : (float, float), optional
        Typical knob speed while moving in the estimation and the validation record
        (:func:`~endocal.validation.shift.moving_speed_dps`).
    held : list of str
        :func:`~endocal.validation.shift.covariates_held`, in words: logged conditions that did
        not change, so the experiment does not ask to log one.

    Returns
    -------
    list of Pointer
        ``load`` (friction changed) or ``drift`` (the zero moved), or nothing; ``delay`` and
        ``rate`` instead of (or, when a logged condition changed too, beside) ``load`` when
        the loop changed the way the speed did.
    """
    if shift is None or scan.scheme != "estimation/validation" or not shift.rmse_deg > 0:
        return []
    best = min([scan.baseline_rmse_heldout_deg] + [s.rmse_heldout_deg for s in scan.tested])
    fr, zr, base = shift.friction_rmse_deg, shift.zero_rmse_deg, shift.rmse_deg
    if not (fr <= SHIFT_CUT * base and fr <= SHIFT_CUT * best):
        return []
    if not 0.5 <= shift.gain <= 2.0:
        # the slope more than doubled or halved: no change of friction between two records does
        # that; the model is read where it was never fitted (a record beyond its range: +64
        # million % was said), which validate's range warning already says
        return []
    fitted = f"with the estimation record's parameters the validation RMSE is {base:.3g} deg"
    seen = ("; " + "; ".join(covariates)) if covariates else ""
    zero_effects, friction_effects = declaring("time"), declaring("load")
    if base - zr >= 0.75 * (base - fr):  # the zero alone does most of it
        return [Pointer(
            effect,
            f"{fitted}; shifting the prediction by {shift.zero_deg:+.3g} deg, fitted on this record alone, brings it "
            f"to {zr:.3g} deg (-{100 * (1 - zr / base):.0f} %){seen}",
            "untested",
            "the zero moved between the records (slow drift or creep in the time between them, a sensor re-mounted, "
            "a knob re-homed, the probe re-seated): a drift fitted within the estimation record cannot know it",
            "home the knobs and keep the base sensor fixed the same way before every record, and record estimation "
            "and validation data back to back; a drift that goes on across records shows in one long record with "
            "drift fitted on its first part") for effect in zero_effects]
    wider = "wider" if shift.width_deg > 0 else "narrower"
    evidence = (f"{fitted}; a loop {abs(shift.width_deg):.3g} knob {shift.cmd_unit} per side {wider} with "
                f"{100 * (shift.gain - 1):+.0f} % slope, fitted on this record alone, brings it to {fr:.3g} deg "
                f"(-{100 * (1 - fr / base):.0f} %)")
    out = []
    if speeds_dps is not None and min(speeds_dps) > 0:
        ratio = speeds_dps[1] / speeds_dps[0]
        if (shift.width_deg > 0 and ratio >= SPEED_RATIO) or (shift.width_deg < 0 and ratio <= 1 / SPEED_RATIO):
            pace = f"{ratio:.2g} times as fast" if ratio > 1 else f"{1 / ratio:.2g} times slower"
            for effect in declaring("speed"):
                out.append(Pointer(
                    effect,
                    f"{evidence}; the knob moves {pace} here ({speeds_dps[1]:.3g} vs {speeds_dps[0]:.3g} "
                    f"{shift.cmd_unit}/s while "
                    f"moving)",
                    "untested",
                    "a lag or a friction that grows with speed makes the loop wider the faster the knob moves, and the "
                    "estimation record does not move at this record's speeds: candidates fitted there cannot tell "
                    "them from the loop's width",
                    f"record estimation data at several speeds, spanning this record's ({EFFECTS[effect].protocol}), "
                    "and validate again"))
            if not covariates:
                return out
    # a condition constant within each record is confounded with the records (their motion, their
    # start, the base's misfit): only the same motion at two of its values, or a change within a run, shows it
    same = ("record the same motion at the earlier value and at a new one (or change it during a run)")
    if covariates:
        column = covariates[0].split("'")[1]
        experiment = (f"{same} with '{column}' logged as here, fit {{effect}}:{column} on them and validate on another")
    elif held:
        experiment = (f"{'; '.join(held)}, so what changed is not what is logged: log that condition (tendon "
                      "pretension, insertion-tube shape, lubrication) as a column of every record, "
                      f"{same}, fit {{effect}}:COLUMN on them and validate on another")
    else:
        experiment = (f"log the condition as a column of every record (e.g. sheath_wrap_deg), {same}, fit "
                      "{effect}:COLUMN on them and validate on another")
    return out + [Pointer(
        effect,
        f"{evidence}{seen}",
        "untested",
        "the friction changed between the records (insertion-tube curvature, tendon tension, lubrication): every "
        "candidate is fitted on the estimation record, which holds one condition",
        experiment.format(effect=effect)) for effect in friction_effects]
