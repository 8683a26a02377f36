"""Which physical effect is the model missing: scan the effect catalog with blocked cross-validation.

For every effect of :data:`endocal.models.EFFECTS` the model does not have yet (and, for
``load``, every varying extra column), the augmented model ``base + effects + candidate``
is fitted and its error is measured on data it was not fitted on; the model as it stands
is refitted the same way, so both face the same held-out data.

Cross-validation (rolling origin, contiguous blocks)
    The first ``train_frac`` of the record is training data only; the rest is cut into
    ``folds`` contiguous test blocks. Fold ``k`` fits on everything before block ``k`` and
    predicts block ``k`` by running the fitted model over the record from its start (so the
    hysteresis operators, delays and creep states enter the block with the history they
    really had). Training data is always one run from the start: hysteresis memory and
    time-based effects (drift, creep, delay) would be broken by holes cut into the record,
    and the model fit takes no sample mask. Held-out data never precedes its training data,
    the honest direction for time series.

Test (autocorrelation-aware, paired)
    The per-sample loss differential ``d_t = e_base(t)^2 - e_cand(t)^2`` on the held-out
    samples (Diebold & Mariano, J. Bus. Econ. Stat. 13, 1995) is averaged over contiguous
    blocks three times as long as the errors' correlation time
    (:func:`endocal.validation.metrics.block_length`, the shorter of the two models'), and the block means are tested with a
    one-sided Wilcoxon signed-rank test (candidate better). The p-values of all candidates
    are Holm-corrected (Holm, Scand. J. Statist. 6, 1979).

A candidate is a *suspect* when its corrected p-value is below ``alpha`` *and* it cuts the
held-out RMSE by at least ``min_gain_pct``: with thousands of samples, statistics alone
would flag a term that absorbs a sliver of a model's structural mismatch; the effect size
keeps a model that already explains the data near its noise floor free of false alarms.
Suspects are ranked by held-out gain.
"""

from __future__ import annotations

import contextlib
import copy
import dataclasses
import math
import re
import shlex
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import wilcoxon

from endocal.errors import ModelError
from endocal.models import EFFECTS, HysteresisData, make_model
from endocal.models.base import HysteresisModel
from endocal.models.data import OTHER_CMD
from endocal.models.start import RecordStart, estimate_starts
from endocal.validation.data import is_constant, load_candidates, prefix
from endocal.validation.metrics import block_length
from endocal.validation.parallel import map_jobs
from endocal.validation.regimes import hold_mask, turning_points
from endocal.validation.units import Units, make_units

try:  # BLAS threads fight each other on the many small least-squares problems of a scan
    from threadpoolctl import threadpool_limits
except ImportError:  # pragma: no cover - threadpoolctl is a declared dependency
    threadpool_limits = None

#: Pairs of effects that can explain the same residual, and the experiment that tells them apart.
TELL_APART = {
    frozenset({"delay", "rate"}): (
        "a delay shifts the whole response in time at every speed, while speed-dependent friction widens "
        "the loop only when the knob moves fast: run `chirp` (or `sine-set`) and compare the loop at low and "
        "high frequency, or `staircase`: a delay shows as the same lag at the start of every step"),
    frozenset({"creep", "drift"}): (
        "creep relaxes after each motion and stops, drift keeps going at a constant rate: run `staircase` "
        "(creep restarts at every step) and `hold` (drift keeps going with the knob still)"),
    frozenset({"deadzone", "envelope"}): (
        "a dead zone appears after every reversal, wherever it happens, while the envelope depends on the "
        "knob position only: run `sine` with an offset (reversals away from neutral)"),
}


@dataclass(frozen=True)
class Suspect:
    """One candidate effect, tested.

    Attributes
    ----------
    effect : str
        The effect as ``--effects`` writes it (``delay``, ``load:sheath_wrap_deg``).
    column : str or None
        The covariate column of a ``load`` term.
    gain_pct : float
        Held-out RMSE improvement over the model as it stands, percent (negative: worse).
    p_value : float
        Holm-corrected one-sided p-value of that improvement.
    p_raw : float
        Uncorrected p-value.
    rmse_heldout_deg, base_rmse_heldout_deg : float
        Held-out RMSE with and without the candidate (deg).
    significant : bool
        Listed as a suspect (``p_value < alpha`` and ``gain_pct >= min_gain_pct``).
    command : str
        The command that refits the model with the candidate.
    cause, signature, protocol : str
        From the effect catalog: physical cause, residual signature, revealing protocol.
    n_blocks : int
        Independent blocks in the paired test.
    screened : bool
        Not refitted beyond the first fold: its training fit gained too little (see
        :func:`scan_effects`).
    caution : str
        Under the estimation/validation scheme, why the candidate may stand in for something
        it does not model: its own parameters that its fit left at a nonzero bound
        (``delay_s = -0.5 sits at its lower bound ...``; a share at its zero bound is the term
        switched off, not stretched), or values its physics cannot have
        (:meth:`~endocal.models.effects.base.Effect.implausible`); such a suggestion ranks
        after those without.
    evidence : str
        ``significant``, ``not significant``, or ``not enough evidence (N units)`` when the
        validation data holds too few independent units for any p-value to reach ``alpha``
        (the candidate is then listed as a suggestion on its gain alone).
    """

    effect: str
    column: str | None
    gain_pct: float
    p_value: float
    p_raw: float
    rmse_heldout_deg: float
    base_rmse_heldout_deg: float
    significant: bool
    command: str
    cause: str
    signature: str
    protocol: str
    n_blocks: int
    screened: bool = False
    evidence: str = ""
    caution: str = ""

    def to_dict(self) -> dict:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


@dataclass(frozen=True)
class ScanResult:
    """Result of :func:`scan_effects`.

    Attributes
    ----------
    suspects : tuple of Suspect
        Significant candidates, most likely (largest held-out gain) first. Under the
        estimation/validation scheme, when none is significant, the candidates that still
        clear the gain bar, as suggestions (their ``evidence`` says why they are not
        significant: too few units, or a gain not consistent across them); empty when no
        candidate lowers the error.
    tested : tuple of Suspect
        Every candidate tested, by decreasing gain.
    baseline_rmse_heldout_deg : float
        Held-out RMSE of the model as it stands (refitted fold by fold).
    untestable : dict
        Effect -> why this data cannot reveal it (not tested).
    notes : tuple of str
        Ambiguities and identifiability, in words.
    folds, stride, n_samples : int
        Test blocks, decimation step and samples scanned (rolling origin); under the
        estimation/validation scheme ``folds`` is 0 and ``stride``/``n_samples`` are those
        of the estimation data the candidates were fitted on.
    scheme : {"estimation/validation", "rolling-origin", "none"}
        How held-out errors were made: candidates fitted on separate estimation data and
        scored on the validation data, or rolling-origin cross-validation on the validation
        data alone; ``none`` when the data could not support either (``scheme_reason`` says why).
    scheme_reason : str
        Why this scheme ran, in words.
    units : dict or None
        The validation data's units of the paired test (estimation/validation scheme).
    min_units : int
        Fewest units with which the best candidate could reach significance.
    still_blocks : int
        Rolling-origin held-out blocks in which this axis's knob rests (:func:`still_blocks`).
    """

    suspects: tuple[Suspect, ...]
    tested: tuple[Suspect, ...]
    baseline_rmse_heldout_deg: float
    untestable: dict = field(default_factory=dict)
    notes: tuple[str, ...] = ()
    folds: int = 0
    stride: int = 1
    n_samples: int = 0
    alpha: float = 0.05
    min_gain_pct: float = 0.0
    scheme: str = "rolling-origin"
    scheme_reason: str = ""
    units: dict | None = None
    min_units: int = 0
    still_blocks: int = 0

    @property
    def thin_evidence(self) -> bool:
        """True when the data holds too few units for any candidate to reach significance."""
        return any(s.evidence.startswith("not enough") for s in self.tested)

    def to_dict(self) -> dict:
        test = ("sign-flip randomisation test on per-unit loss differentials of the validation data, Holm-corrected"
                if self.scheme == "estimation/validation" else
                "Wilcoxon signed-rank on block-mean loss differentials, Holm-corrected")
        return {
            "suspects": [s.to_dict() for s in self.suspects],
            "tested": [s.to_dict() for s in self.tested],
            "baseline_rmse_heldout_deg": self.baseline_rmse_heldout_deg,
            "untestable": dict(self.untestable),
            "notes": list(self.notes),
            "cv": {"scheme": self.scheme, "reason": self.scheme_reason, "folds": self.folds, "stride": self.stride,
                   "n_samples": self.n_samples, "alpha": self.alpha, "min_gain_pct": self.min_gain_pct,
                   "units": self.units, "min_units": self.min_units, "test": test,
                   "still_blocks": self.still_blocks},
        }


# ---------------------------------------------------------------------------- folds
def fold_bounds(n_samples: int, folds: int, train_frac: float = 0.5) -> list[tuple[int, int]]:
    """``(train_end, test_end)`` of each rolling-origin fold: train on ``[0, train_end)``, test ``[train_end, test_end)``.

    On data of several runs the bounds are read as fractions of ``n_samples`` and applied to
    every run at once (:func:`fold_split`).
    """
    first = int(round(train_frac * n_samples))
    edges = np.linspace(first, n_samples, folds + 1).round().astype(int)
    return [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:])]


def fold_split(data: HysteresisData, bound: tuple[int, int]) -> tuple[HysteresisData, HysteresisData, np.ndarray]:
    """Training data, the data to run the fitted model over, and the held-out positions in the latter.

    One run: train on ``[0, a)``, run over ``[0, b)``, hold out ``[a, b)``. Several runs (a
    random input and a chirp, say): the same fractions ``a/n`` and ``b/n`` of *every* run, so
    each training block holds every kind of motion the held-out blocks do; rolling the origin
    over the runs laid end to end would fit on the first runs and ask for the last. That
    holds while the first half of every run already spans its command range
    (:func:`runs_cover_their_range`); runs that go somewhere new later (a staircase up, then
    down) are laid end to end instead, so no fold asks a model for commands it never saw.

    Returns
    -------
    train, evaluate : HysteresisData
        Each run's prefix up to its training end and up to its test end (runs kept apart).
    held : ndarray of int
        Positions in ``evaluate`` of the held-out samples, run by run.
    """
    a, b = bound
    if data.run_starts.size <= 1 or not runs_cover_their_range(data):
        return prefix(data, a), prefix(data, b), np.arange(a, b)
    n = data.n_samples
    train_idx, eval_idx, held = [], [], []
    for sl in data.run_slices():
        length = sl.stop - sl.start
        ra, rb = int(round(a / n * length)), int(round(b / n * length))
        train_idx.append(np.arange(sl.start, sl.start + ra))
        held.append(sum(len(i) for i in eval_idx) + np.arange(ra, rb))
        eval_idx.append(np.arange(sl.start, sl.start + rb))
    return data.take(train_idx), data.take(eval_idx), np.concatenate(held)


def runs_cover_their_range(data: HysteresisData, train_frac: float = 0.5, min_cover: float = 0.75) -> bool:
    """True when the first ``train_frac`` of every run spans at least ``min_cover`` of that run's command range.

    A band-limited random input's first half spans ~85 % of its range (its peaks fall
    anywhere: a model trained on it clamps a little), a chirp's or damped sine's 100 %, a
    staircase up then down 50 % (a model trained on it would have to guess half the range).
    """
    for sl in data.run_slices():
        u = data.cmd_deg[sl]
        head = u[: max(1, int(round(train_frac * u.size)))]
        span = float(np.ptp(u))
        if span > 0 and float(np.ptp(head)) < min_cover * span:
            return False
    return True


def check_cv_data(data: HysteresisData, folds: int, train_frac: float = 0.5, min_block: int = 30) -> None:
    """Refuse data too short for ``folds``-fold blocked cross-validation.

    Raises
    ------
    ModelError
        Fewer than ``min_block`` samples per test block, or a first training block without
        two direction reversals (the model could not be fitted on it).
    """
    if not isinstance(folds, (int, np.integer)) or isinstance(folds, bool) or folds < 2:
        raise ModelError(f"folds must be an integer >= 2, got {folds!r}")
    n = data.n_samples
    need = int(math.ceil(folds * min_block / (1 - train_frac)))
    if n < need:
        raise ModelError(f"data too short for {folds}-fold blocked cross-validation: {n} samples, need at least "
                         f"{need} ({min_block} per held-out block); give a longer run or fewer --folds")
    first = fold_split(data, fold_bounds(n, folds, train_frac)[0])[0]
    n_turns = int(turning_points(first).size)
    if n_turns < 2:
        if np.ptp(first.cmd_deg) <= STILL_FRAC * np.ptp(data.cmd_deg) and turning_points(data).size >= 2:
            # not short: this knob rests, then moves (a sine-set moves one knob, then the other)
            raise ModelError(f"this axis reverses {int(turning_points(data).size)} times in the record but its knob "
                             f"rests through the first {first.n_samples} samples (the first training block), so no "
                             "model can be fitted there")
        raise ModelError(f"data too short for blocked cross-validation: the first {first.n_samples} samples (the first "
                         f"training block) hold {n_turns} direction reversal(s), a hysteresis model needs at least 2; "
                         "give a longer run")


#: A knob "rests" in a stretch of record when its command stays within this fraction of its
#: range over the record: 2 % of a 120 deg sweep is 2.4 deg, below any loop a tendon drive draws.
STILL_FRAC = 0.02


def still_blocks(data: HysteresisData, bounds: Sequence[tuple[int, int]]) -> int:
    """Held-out blocks in which this axis's knob rests (:data:`STILL_FRAC`) while the other moves:
    they test nothing of its hysteresis, only where the model puts the resting bend."""
    span = float(np.ptp(data.cmd_deg))
    still = 0
    for bd in bounds:
        _, over, held = fold_split(data, bd)
        cmd = over.cmd_deg[held]
        still += int(cmd.size == 0 or np.ptp(cmd) <= STILL_FRAC * span)
    return still


def _template(model: HysteresisModel, effects: Sequence[str]) -> HysteresisModel:
    return make_model(model.base_name, list(effects), **model.get_settings(), fixed=model.fixed, axis=model.axis,
                      out_of_range="extrapolate")


def effect_labels(model: HysteresisModel) -> list[str]:
    """The model's effects as ``--effects`` writes them."""
    effects = model.effects_ if hasattr(model, "effects_") else model._effects()
    return [e.label for e in effects]


def fold_errors(model: HysteresisModel, effects: Sequence[str], data: HysteresisData,
                bound: tuple[int, int]) -> tuple[np.ndarray, HysteresisModel]:
    """Held-out errors ``pred - meas`` (deg) of ``base + effects`` on one rolling-origin fold, and its fitted model.

    The model is fitted on ``[0, train_end)`` and run over ``[0, test_end)`` from the record's
    start; the errors are those of ``[train_end, test_end)``.
    """
    train, evaluate, held = fold_split(data, bound)
    m = _template(model, effects).fit(train)
    pred = m.predict(evaluate)  # a template extrapolates beyond its fitted range
    return pred[held] - evaluate.meas_deg[held], m


def heldout_errors(model: HysteresisModel, effects: Sequence[str], data: HysteresisData,
                   bounds: Sequence[tuple[int, int]]) -> tuple[np.ndarray, list]:
    """Held-out errors ``pred - meas`` of ``base + effects`` on the rolling-origin folds.

    Parameters
    ----------
    model : HysteresisModel
        Gives the base and its settings (its fitted values are not used).
    effects : sequence of str
        Effects of the refitted models.
    data : HysteresisData
    bounds : list of (train_end, test_end)
        From :func:`fold_bounds`.

    Returns
    -------
    errors : ndarray (n_test,)
        Concatenated over the test blocks (deg).
    fitted : list of HysteresisModel
        The model of each fold.
    """
    out = [fold_errors(model, effects, data, bd) for bd in bounds]
    return np.concatenate([e for e, _ in out]), [m for _, m in out]


def one_blas_thread():
    """Context limiting BLAS to one thread (many small least-squares problems run faster that way)."""
    return threadpool_limits(limits=1, user_api="blas") if threadpool_limits else contextlib.nullcontext()


def paired_test(err_base: np.ndarray, err_cand: np.ndarray) -> tuple[float, int]:
    """One-sided p-value that ``err_cand`` is smaller than ``err_base``, and the number of blocks used.

    Block means of the loss differential ``e_base^2 - e_cand^2`` (blocks three times the
    errors' correlation time), Wilcoxon signed-rank test, alternative "greater".
    """
    d = err_base**2 - err_cand**2
    if not np.any(d):
        return 1.0, 0
    # Blocks of three correlation times: neighbouring block means are then nearly independent
    # (one correlation time leaves them correlated by ~1/e and the test rejects too often).
    # The correlation time is the errors', the shorter of the two models': a systematic error
    # that one model removes (a drift, a lag) makes the other's error and the differential
    # correlated over the whole record, which measures the signal, not the dependence of the noise.
    L = 3 * min(block_length(err_base), block_length(err_cand))
    L = min(L, max(1, d.size // 6))
    nb = d.size // L
    means = d[: nb * L].reshape(nb, L).mean(axis=1)
    if nb < 2 or not np.any(means):
        return 1.0, nb
    return float(wilcoxon(means, alternative="greater").pvalue), nb


def holm(p: Sequence[float]) -> np.ndarray:
    """Holm step-down adjusted p-values (same order as ``p``)."""
    p = np.asarray(p, dtype=float)
    m = p.size
    order = np.argsort(p)
    adj = np.empty(m)
    running = 0.0
    for rank, i in enumerate(order):
        running = max(running, min(1.0, (m - rank) * p[i]))
        adj[i] = running
    return adj


# ---------------------------------------------------------------------------- identifiability
def _one_frequency(data: HysteresisData) -> str | None:
    """Why the data has a single frequency of motion (None when it has several)."""
    turns = turning_points(data)
    t = data.t_s if data.t_s is not None else np.arange(data.n_samples, dtype=float)
    same_run = np.searchsorted(data.run_starts, turns[1:], side="right") == np.searchsorted(
        data.run_starts, turns[:-1], side="right")
    half = np.diff(t[turns])[same_run] if turns.size > 1 else np.array([])
    if half.size < 2:
        return "too few reversals"
    lo, hi = np.quantile(half, [0.1, 0.9])
    return "one frequency only" if hi < 1.5 * lo else None


def _rate_reason(data: HysteresisData) -> str | None:
    why = _one_frequency(data)
    if why is None:
        return None
    return (f"{why}: rate cannot be identified (speed-dependent friction needs the same motion at several "
            "frequencies: run `chirp` or `sine-set`)")


def _delay_reason(data: HysteresisData) -> str | None:
    if data.t_s is None:
        return "no time stamps: delay cannot be identified"
    why = _one_frequency(data)
    if why is None:
        return None
    return (f"{why}: delay cannot be identified (at one frequency a time shift looks like a wider loop: "
            "run `chirp` or `random`)")


def _creep_reason(data: HysteresisData) -> str | None:
    hold = hold_mask(data, 1.0)
    span = float(np.ptp(data.cmd_deg))
    t = data.t_s
    starts = np.flatnonzero(hold & ~np.concatenate([[False], hold[:-1]]))
    for k in starts:
        run0 = data.run_starts[np.searchsorted(data.run_starts, k, side="right") - 1]
        # within this record: several records restart their clocks, so a search over all of t is unordered
        j = int(run0) + int(np.searchsorted(t[run0:k + 1], t[k] - 2.0)) if t is not None else k - 20
        j = max(int(j), int(run0))
        if k > run0 and np.ptp(data.cmd_deg[j:k + 1]) >= 0.05 * span:
            return None
    return ("no holds: creep cannot be identified (it shows as the tip still moving after the knob stops: "
            "run `staircase`)")


def _coupling_reason(data: HysteresisData, where: str = "") -> str | None:
    if OTHER_CMD not in data.extras:
        return "one axis only: coupling cannot be identified (drive both knobs: run `lissajous` or `circle`)"
    if is_constant(data.extras[OTHER_CMD]):
        if where:
            return (f"the other knob never moves in {where}: coupling cannot be fitted there (record estimation "
                    "data in which both knobs move, e.g. `lissajous` or `circle`, or each knob in turn: `sine-set`)")
        return "the other knob never moves: coupling cannot be identified (run `lissajous` or `circle`)"
    return None


def _time_reason(name: str):
    def reason(data: HysteresisData) -> str | None:
        return None if data.t_s is not None else f"no time stamps: {name} cannot be identified"
    return reason


#: Effect name -> check of whether the data can reveal it (None: it can; else why not).
IDENTIFIABILITY = {
    "rate": _rate_reason,
    "creep": _creep_reason,
    "coupling": _coupling_reason,
    "delay": _delay_reason,
    "drift": _time_reason("drift"),
}

#: Effect name -> check of whether its parameters can be fitted at all (the estimation/validation
#: scheme tests every fittable candidate on the separate validation data).
FITTABILITY = {
    "coupling": _coupling_reason,
    "delay": _time_reason("delay"),
    "drift": _time_reason("drift"),
    "creep": _time_reason("creep"),
    "rate": _time_reason("rate"),
}


def takes_column(name: str) -> bool:
    """True for catalog effects that need a column, written ``NAME:COLUMN`` (``load``)."""
    try:
        EFFECTS[name]()
    except (ModelError, TypeError):
        return True
    return False


def settings_args(model: HysteresisModel) -> list[str]:
    """``--set key=value`` for each base setting of ``model`` that differs from its default, so a
    refit keeps the model's structure (``n_knots``, ``n_operators``, ...)."""
    import inspect
    import json

    sig = inspect.signature(type(model).__init__)
    out = []
    for k, v in model.get_settings().items():
        default = sig.parameters[k].default
        if default is not inspect.Parameter.empty and v != default:
            out += ["--set", f"{k}={json.dumps(v)}"]
    return out


def refit_command(data_paths: Sequence[str], axis: str | None, base: str, effects: Sequence[str], out: str,
                  extra_args: Sequence[str] = (), start_from: str | None = None) -> str:
    """``endocal fit hysteresis DATA... --axis AXIS --model BASE --effects E1,E2 [EXTRA...] [--start-from M] --out OUT``.

    ``start_from`` is the model under validation: the scan fitted each candidate starting from
    its parameters (:func:`split_fit`), and the refit does the same, so it is the fit the scan
    scored rather than a fit from scratch that may stop in another local minimum. Arguments are
    quoted for a POSIX shell where they need it (a lab folder with a space in its name).
    """
    parts = ["endocal fit hysteresis", *[str(p) for p in data_paths]]
    if axis:
        parts += ["--axis", axis]
    parts += ["--model", base]
    if effects:
        parts += ["--effects", ",".join(effects)]
    parts += [str(a) for a in extra_args]
    if start_from:
        parts += ["--start-from", str(start_from)]
    parts += ["--out", out]
    return "endocal fit hysteresis " + shlex.join(parts[1:])


def refit_path(model_path: str | None, effect: str, suffix: str = "") -> str:
    """``MODEL-EFFECT.json`` beside ``MODEL.json`` (``load:col`` becomes ``load-col``), with
    ``suffix`` before ``.json`` (``-all`` for a refit on more data than the scan scored)."""
    tag = effect.replace(":", "-") + suffix
    if not model_path:
        return f"model-{tag}.json"
    p = str(model_path)
    stem = p[:-5] if p.endswith(".json") else p
    return f"{stem}-{tag}.json"


# ---------------------------------------------------------------------------- the scan
#: Longest record the scan fits at full rate (longer ones are decimated to about this many
#: samples): a 600 s record at 100 Hz is scanned at 8 Hz, still >= 25 samples per cycle of
#: the <= 0.3 Hz loops a knob draws, and the budget that keeps the scan of every catalog
#: effect on 60 000 samples under 30 s (bench/bench_scan.py).
MAX_SCAN_SAMPLES = 5000


def candidate_effects(model: HysteresisModel, data: HysteresisData, candidates: Sequence[str] | None,
                      load_columns: Sequence[str] | None, bending_axes: Sequence[str], *,
                      train: HysteresisData, rolling: bool) -> tuple[list[str], dict[str, str]]:
    """The catalog effects to test, and why the others cannot be tested on this data.

    Parameters
    ----------
    model : HysteresisModel
        The model as it stands (its effects are not candidates).
    data : HysteresisData
        All the data the scan uses (load candidates must vary in it).
    candidates, load_columns : sequence of str, optional
        As :func:`scan_effects`.
    bending_axes : sequence of str
        Knob columns that are not load candidates.
    train : HysteresisData
        The data candidates are fitted on (the first training block, or the estimation data):
        an effect whose parameters it cannot show (the other knob at rest, no time stamps)
        is not fitted.
    rolling : bool
        Rolling-origin cross-validation: effects that need several speeds (``rate``,
        ``delay``) or holds (``creep``) to be told from a wider loop are tested only on data
        that has them. Under the estimation/validation scheme every fittable candidate is
        tested: the separate validation data decides.

    Returns
    -------
    tested : list of str
    untestable : dict of str to str
    """
    have = effect_labels(model)
    have_names = {lab.partition(":")[0] for lab in have}
    untestable: dict[str, str] = {}
    if candidates is None:
        cands: list[str] = []
        for name in EFFECTS:
            if takes_column(name):
                constant: list[str] = []
                if load_columns is None:
                    cols, constant = load_candidates(data, bending_axes)
                else:
                    cols = list(load_columns)
                modelled = [c for c in cols if f"{name}:{c}" in have]
                cols = [c for c in cols if c not in modelled]
                if not cols and not modelled:
                    where = "the estimation data" if not rolling else "the data"
                    what = (f"no extra column varies in {where} ({len(constant)} constant)" if constant else
                            f"{where} has no extra column")
                    untestable[name] = (f"{what}: {name} cannot be identified (log a covariate such as "
                                        "sheath_wrap_deg, at two or more values)")
                cands += [f"{name}:{c}" for c in cols]
            elif name not in have_names:
                cands.append(name)
    else:
        cands = [c for c in candidates if c not in have]
    tested = []
    for c in cands:
        name = c.partition(":")[0]
        check = (IDENTIFIABILITY if rolling else FITTABILITY).get(name)
        reason = check(data) if check is not None else None
        if reason is None and name == "coupling":
            reason = _coupling_reason(train, where="the estimation data" if not rolling else
                                      f"the first training block (the first {train.n_samples} of {data.n_samples} "
                                      "samples)")
        if reason is not None:
            untestable[c] = reason
        else:
            tested.append(c)
    return tested, untestable


def min_units_for(n_candidates: int, alpha: float) -> int:
    """Fewest paired units with which the best of ``n_candidates`` can reach Holm-corrected ``alpha``.

    The smallest one-sided p-value of the exact sign-flip test on ``n`` units
    (:func:`unit_test`) is ``2**-n`` (every unit in favour); Holm multiplies the smallest
    p-value by the number of candidates.
    """
    return max(1, int(math.ceil(math.log2(max(n_candidates, 1) / alpha))))


def unit_test(err_base: np.ndarray, err_cand: np.ndarray, units: Units, n_flips: int = 20000) -> float:
    """One-sided p-value that ``err_cand``'s mean squared error is smaller than ``err_base``'s, unit by unit.

    The loss differential ``d_t = e_base(t)^2 - e_cand(t)^2`` (Diebold & Mariano 1995) is
    summed over each unit (a half-cycle or decorrelation block of the validation data,
    :func:`~endocal.validation.units.make_units`); the units are nearly independent, the
    samples within one are not. Under the null hypothesis that neither model is better,
    each unit's sum is as likely positive as negative, so the observed total
    ``sum_u D_u`` (which is ``n`` times the MSE difference, the quantity the gain reports)
    is compared with its sign-flip randomisation distribution (Fisher's paired
    randomisation test): exact over all ``2**n`` flips for ``n <= 16`` units, else
    ``n_flips`` seeded random flips. Unlike a rank test on the units it tests the total
    error, so a candidate that removes a large error on a few units and costs a little on
    many is judged by what it does to the RMSE.
    """
    d = err_base**2 - err_cand**2
    sums = np.array([d[a:b].sum() for a, b in units.bounds])
    observed = float(sums.sum())
    if sums.size < 1 or observed <= 0 or not np.any(sums):
        return 1.0
    n = sums.size
    if n <= 16:
        signs = 1 - 2 * ((np.arange(2**n)[:, None] >> np.arange(n)) & 1)
        return float(np.mean(signs @ sums >= observed * (1 - 1e-12)))
    rng = np.random.default_rng(0)
    # drawn 1000 flips at a time (an even count of draws per call keeps the generator's stream, so the
    # p-value is the one a single (n_flips, n) draw gives): the whole matrix would hold 16 bytes per flip
    # and unit (int64 draws and their float signs), 300 MB for an hour's record of 1000 half-cycles
    hits = 0
    for a in range(0, n_flips, 1000):
        flips = rng.choice(np.array([-1.0, 1.0]), size=(min(1000, n_flips - a), n)) @ sums
        hits += np.count_nonzero(flips >= observed * (1 - 1e-12))
    return float((1 + hits) / (1 + n_flips))


def predict_scored(model: HysteresisModel, data: HysteresisData) -> tuple[np.ndarray, int, list[RecordStart]]:
    """Predicted angle (deg) as ``validate`` scores a model: beyond the fitted range the model
    continues, and each record starts in its estimated state.

    A command beyond the range the model was fitted on is run through the model's own
    branches continued (B-spline end tangents, straight lines, saturated plays), not clamped:
    clamping holds the predicted angle still while the tip keeps bending, so a validation
    run 10 deg wider than the estimation run would be scored on that artefact (on a
    simulated sweep, 3.3 deg instead of the model's 0.8). A record that starts where a longer
    motion left the knob is run from its estimated start (:mod:`endocal.models.start`), as the
    fit runs its own records.

    Parameters
    ----------
    model : HysteresisModel
        A fitted model (left unchanged: a shallow copy is switched to extrapolate).
    data : HysteresisData
        Commands (deg) and whatever else the model's effects read; without the measured
        angle every record starts from rest.

    Returns
    -------
    predicted_deg : (n,) array
        Predicted bending angle, deg.
    n_beyond : int
        Samples whose command lies beyond the model's fitted range ``cmd_range_deg_``.
    starts : list of RecordStart
        The records run from an estimated start.
    """
    m = copy.copy(model)
    m.out_of_range = "extrapolate"
    lo, hi = model.cmd_range_deg_
    pred, starts = estimate_starts(m.predict, columns_read(model, data))
    return pred, int(np.sum((data.cmd_deg < lo) | (data.cmd_deg > hi))), starts


def columns_read(model: HysteresisModel, data: HysteresisData) -> HysteresisData:
    """``data`` with only the extra columns ``model``'s effects read (coupling, load), as views.

    A prediction needs no other column, and :func:`~endocal.models.start.estimate_starts` and
    :func:`~endocal.models.start.with_lead_ins` copy every column they are given (each lead-in
    tried is a record's length and more).
    """
    read = {c for e in getattr(model, "effects_", []) if (c := getattr(e, "column", None))}
    if not set(data.extras) - read:
        return data
    return dataclasses.replace(data, extras={k: v for k, v in data.extras.items() if k in read})


def predict_extrapolated(model: HysteresisModel, data: HysteresisData) -> tuple[np.ndarray, int]:
    """The prediction and samples beyond the fitted range of :func:`predict_scored`."""
    return predict_scored(model, data)[:2]


def _predict_errors(model: HysteresisModel, data: HysteresisData) -> np.ndarray:
    return predict_extrapolated(model, data)[0] - data.meas_deg


def fitted_on(model: HysteresisModel, data: HysteresisData) -> bool:
    """Whether ``model`` was fitted on exactly ``data`` (the per-run fingerprints its fit recorded).

    Then the model *is* its structure fitted on that estimation data: scoring it as it stands
    is what a refit would do, minus the chance of the refit stopping in another local minimum
    (a B-spline + delay refitted from its own values once ended 68 % worse on the validation
    record than the file it came from).
    """
    recorded = getattr(model, "training_data_", None) or []
    return bool(recorded) and [r.get("sha256") for r in recorded] == [f["sha256"] for f in data.fingerprint()]


def split_fit(model: HysteresisModel, effects: Sequence[str], train: HysteresisData, stride: int = 1) -> HysteresisModel:
    """``base + effects`` (with ``model``'s settings) fitted on ``train``, every ``stride``-th sample.

    The effects ``model`` already has start from its fitted values (it was fitted on this
    estimation data), so only a new effect searches its start candidates.
    """
    dt = train.decimate(stride) if stride > 1 else train
    return _template(model, effects).fit_from(model, dt)


def predict_errors(model: HysteresisModel, data: HysteresisData) -> np.ndarray:
    """``pred - meas`` (deg) of a fitted model run over ``data`` from its start (continued beyond its fitted range)."""
    return _predict_errors(model, data)


_AT_BOUND = re.compile(r"sits at its (?:lower|upper) bound (\S+):")


def _split_candidate(model: HysteresisModel, effects: Sequence[str], train: HysteresisData,
                     val: HysteresisData) -> tuple[np.ndarray, list[str]]:
    """Validation errors of ``base + effects`` fitted on ``train``, and the cautions about the
    effects ``model`` lacks (:attr:`Suspect.caution`)."""
    m = split_fit(model, effects, train)
    have = set(effect_labels(model))
    new = [e for e in m.effects_ if e.label not in have]
    prefixes = tuple(e.prefix + "_" for e in new)
    cautions = [w for w in m.fit_report_.warnings if prefixes and w.startswith(prefixes)
                and (b := _AT_BOUND.search(w)) and float(b.group(1)) != 0.0]
    cautions += [c for e in new if (c := e.implausible(m.effect_params(e), train))]
    if any(e.name == "creep" for e in new) and _creep_reason(train) and _creep_reason(val):
        # creep shows itself where the knob rests after a move; fitted and scored on motion alone
        # its slow memory takes up smoother reversals, a lag or how the records start, and its
        # refits failed on other records of the same plant (red-team runs, README known gaps)
        cautions.append("no record holds the knob still after a move, where creep shows itself (the tip still "
                        "moving after the knob stops): fitted on motion alone it may stand for smoother reversals, a "
                        "lag or how the records start; record a `staircase` to confirm it")
    return _predict_errors(m, val), cautions


def split_errors(model: HysteresisModel, effects: Sequence[str], train: HysteresisData, val: HysteresisData,
                 stride: int = 1) -> np.ndarray:
    """Validation errors ``pred - meas`` (deg) of ``base + effects`` fitted on ``train`` (every ``stride``-th sample)."""
    return _predict_errors(split_fit(model, effects, train, stride), val)


def scan_split(model: HysteresisModel, train: HysteresisData, val: HysteresisData, *, alpha: float = 0.05,
               min_gain_pct: float = 10.0, candidates: Sequence[str] | None = None,
               load_columns: Sequence[str] | None = None, bending_axes: Sequence[str] = (),
               max_samples: int = MAX_SCAN_SAMPLES, data_paths: Sequence[str] = ("DATA",),
               model_path: str | None = None, refit_args: Sequence[str] = (),
               scheme_reason: str = "", jobs: int | None = None, refit_suffix: str = "") -> ScanResult:
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
    significant: ``"not enough evidence (N units, M needed)"`` when ``val`` holds fewer units
    than any candidate would need to reach ``alpha`` (:func:`min_units_for`), else the p-value.

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
        The estimation data, for the refit commands (the validation data is not folded in).
    refit_args : sequence of str
        Further options of the refit command (``--planes planes.json``).
    scheme_reason : str
        Why this scheme runs, recorded in the result.
    jobs : int, optional
        Processes for the fits (:func:`endocal.validation.parallel.n_jobs`).
    refit_suffix : str
        Ends the refit's file name (:func:`refit_path`): ``-all`` when ``data_paths`` fold the
        validation data in, so that model does not take the name of the one the scan scored.

    Returns
    -------
    ScanResult

    Raises
    ------
    ModelError
        The estimation data cannot be fitted (no reversal, too few samples), or the model
        as it stands cannot be refitted on it.
    """
    if train.meas_deg is None or val.meas_deg is None:
        raise ModelError("validation needs the measured angle meas_deg (deg) in estimation and validation data")
    check_fit_data(train, "estimation data")
    stride = max(1, int(math.ceil(train.n_samples / max_samples)))
    dt = train.decimate(stride) if stride > 1 else train
    have = effect_labels(model)
    tested_cands, untestable = candidate_effects(model, dt, candidates, load_columns, bending_axes,
                                                 train=dt, rolling=False)
    # the model as it stands, fitted on this very estimation data, is scored as it is (a refit of
    # the same structure on the same data could only stop elsewhere); else its structure is refitted
    as_is = fitted_on(model, train)
    with one_blas_thread():
        results = map_jobs(lambda effects: _split_candidate(model, effects, dt, val),
                           ([] if as_is else [have]) + [have + [c] for c in tested_cands], jobs)
    if as_is:
        results = [(predict_errors(model, val), [])] + results
    if isinstance(results[0], ModelError):
        raise ModelError(f"the model as it stands cannot be refitted on the estimation data: {results[0]}") from None
    err_base = results[0][0]
    fitted, cautions = [], {}
    for c, res in zip(tested_cands, results[1:]):
        if isinstance(res, ModelError):
            untestable[c] = f"could not be fitted on the estimation data ({res})"
        else:
            fitted.append((c, res[0]))
            cautions[c] = "; ".join(res[1])
    rmse_base = float(np.sqrt(np.mean(err_base**2)))
    # units sized by the error of the model as it stands: the same for every candidate (a p-value
    # does not depend on which others were tested) and for the report's ladder, which has only the pair
    units = make_units(val, [err_base])
    need = min_units_for(len(fitted), alpha)
    thin = units.n < need
    raw = [unit_test(err_base, e, units) for _, e in fitted]
    adj = holm(raw) if raw else np.array([])
    tested, errs = [], {}
    for (c, err), p, pa in zip(fitted, raw, adj):
        name, _, col = c.partition(":")
        cls = EFFECTS[name]
        rmse = float(np.sqrt(np.mean(err**2)))
        gain = 100.0 * (1.0 - rmse / rmse_base) if rmse_base > 0 else 0.0
        significant = bool(pa < alpha and gain >= min_gain_pct)
        evidence = (f"not enough evidence ({units.n} units, {need} needed)" if thin else
                    "significant" if significant else f"not significant (p = {pa:.2g} over {units.n} {units.kind}s)")
        cmd = refit_command(data_paths, model.axis, model.base_name, have + [c],
                            refit_path(model_path, c, refit_suffix), [*refit_args, *settings_args(model)],
                            start_from=model_path)
        tested.append(Suspect(effect=c, column=col or None, gain_pct=gain, p_value=float(pa), p_raw=float(p),
                              rmse_heldout_deg=rmse, base_rmse_heldout_deg=rmse_base, significant=significant,
                              command=cmd, cause=cls.cause, signature=cls.signature, protocol=cls.protocol,
                              n_blocks=units.n, evidence=evidence, caution=cautions[c]))
        errs[c] = err
    tested.sort(key=lambda s: -s.gain_pct)
    # Significant candidates are suspects. Without one, a candidate that still cuts the validation
    # RMSE by the gain bar is listed as a suggestion with its evidence: it was fitted on other data
    # and measured here, so the refit it names lowers this error by that much; the test only says
    # the gain is not consistent enough across units to rule out chance.
    suspects = [s for s in tested if s.significant] or [s for s in tested if s.gain_pct >= min_gain_pct]
    # a candidate with a caution (a delay at its -0.5 s bound, a drift too fast to be one) ranks after the others
    suspects.sort(key=lambda s: bool(s.caution))
    notes = _demoted(suspects) + (_ambiguities(suspects, errs, alpha) if any(s.significant for s in suspects) else [])
    notes += [f"{k}: {v}" for k, v in untestable.items()]
    if thin and fitted:
        notes.append(f"the validation data holds {units.n} {units.kind}s; with {len(fitted)} candidates at least "
                     f"{need} are needed before any can be significant at {alpha:g}: candidates are ranked by their "
                     "validation gain alone; validate on a longer record (or more records) to test them")
    if stride > 1:
        notes.append(f"candidates fitted on 1 estimation sample in {stride} ({dt.n_samples} of {train.n_samples}) to "
                     "keep the scan quick; the printed refit fits every sample, so its validation RMSE can differ "
                     "from the candidate's by a few per cent")
    return ScanResult(tuple(suspects), tuple(tested), rmse_base, untestable, tuple(notes), 0, stride,
                      dt.n_samples, alpha, min_gain_pct, scheme="estimation/validation", scheme_reason=scheme_reason,
                      units=units.to_dict(), min_units=need)


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
                 refit_args: Sequence[str] = (), scheme_reason: str = "", jobs: int | None = None) -> ScanResult:
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
        Where the data and model came from, for the refit commands.
    refit_args : sequence of str
        Further options of the refit commands (``--planes planes.json``).
    scheme_reason : str
        Why this scheme runs, recorded in the result.
    jobs : int, optional
        Processes for the fits (:func:`endocal.validation.parallel.n_jobs`).

    Returns
    -------
    ScanResult

    Raises
    ------
    ModelError
        Data too short for the cross-validation, or the model as it stands cannot be
        refitted on the first training block.
    """
    if data.meas_deg is None:
        raise ModelError("validation needs the measured angle meas_deg (deg)")
    stride = max(1, int(math.ceil(data.n_samples / max_samples)))
    d = data.decimate(stride) if stride > 1 else data
    check_cv_data(d, folds, train_frac)
    bounds = fold_bounds(d.n_samples, folds, train_frac)
    have = effect_labels(model)
    # what the first training block cannot show, no fold can be fitted for
    first_train = fold_split(d, bounds[0])[0]
    tested_cands, untestable = candidate_effects(model, d, candidates, load_columns, bending_axes,
                                                 train=first_train, rolling=True)

    with one_blas_thread():
        base_folds = map_jobs(lambda bd: fold_errors(model, have, d, bd), bounds, jobs)
        for f in base_folds:
            if isinstance(f, ModelError):
                raise f
        err_base = np.concatenate([e for e, _ in base_folds])
        base_train_rmse = base_folds[0][1].fit_report_.rmse_deg
        rmse_base = float(np.sqrt(np.mean(err_base**2)))

        def candidate(c: str):
            first = fold_errors(model, have + [c], d, bounds[0])
            train_gain = 100.0 * (1.0 - first[1].fit_report_.rmse_deg / base_train_rmse) if base_train_rmse > 0 else 0.0
            if train_gain < screen_pct * min_gain_pct:
                # screened on its training fit alone: no held-out data was looked at to decide
                e0 = first[0]
                rmse0 = float(np.sqrt(np.mean(e0**2)))
                base0 = float(np.sqrt(np.mean(err_base[:e0.size] ** 2)))
                return (c, None, rmse0 * rmse_base / base0 if base0 > 0 else rmse0, 1.0, 0)
            rest = [fold_errors(model, have + [c], d, bd) for bd in bounds[1:]]
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
        name, _, col = c.partition(":")
        cls = EFFECTS[name]
        gain = 100.0 * (1.0 - rmse / rmse_base) if rmse_base > 0 else 0.0
        cmd = refit_command(data_paths, model.axis, model.base_name, have + [c], refit_path(model_path, c),
                            [*refit_args, *settings_args(model)], start_from=model_path)
        significant = bool(pa < alpha and gain >= min_gain_pct)
        tested.append(Suspect(effect=c, column=col or None, gain_pct=gain, p_value=float(pa), p_raw=p,
                              rmse_heldout_deg=rmse, base_rmse_heldout_deg=rmse_base,
                              significant=significant, command=cmd,
                              cause=cls.cause, signature=cls.signature, protocol=cls.protocol, n_blocks=nb,
                              screened=err is None, evidence="significant" if significant else "not significant"))
        if err is not None:
            errs[c] = err
    tested.sort(key=lambda s: -s.gain_pct)
    suspects = [s for s in tested if s.significant]
    notes = _ambiguities(suspects, errs, alpha)
    notes += [f"{k}: {v}" for k, v in untestable.items()]
    if stride > 1:
        notes.append(f"scanned 1 sample in {stride} ({d.n_samples} of {data.n_samples})")
    still = still_blocks(d, bounds)
    if still:
        where = (f"all {folds} held-out blocks hold" if still == folds else f"{still} of the {folds} held-out blocks hold")
        notes.insert(0, f"{where} no motion of this axis (its knob rests while the record goes on): there the scan "
                        "scores only where the model puts the resting bend, not its hysteresis; validate on a record "
                        "where this axis moves throughout")
    return ScanResult(tuple(suspects), tuple(tested), rmse_base, untestable, tuple(notes), folds, stride,
                      d.n_samples, alpha, min_gain_pct, scheme="rolling-origin", scheme_reason=scheme_reason,
                      still_blocks=still)


def _demoted(suspects: list[Suspect]) -> list[str]:
    """Notes on suggestions that lower the error more than the first but rank after it (a caution)."""
    if not suspects or suspects[0].caution:
        return []
    top = suspects[0]
    return [f"{s.effect} lowers the validation RMSE more than {top.effect} ({s.rmse_heldout_deg:.3g} vs "
            f"{top.rmse_heldout_deg:.3g} deg) but ranks after it: {s.caution}; it may stand in for something it does "
            "not model (how the records start, a loop shape)" for s in suspects[1:]
            if s.caution and s.rmse_heldout_deg < top.rmse_heldout_deg]


def _ambiguities(suspects: list[Suspect], errs: dict, alpha: float, close_pct: float = 5.0) -> list[str]:
    """Notes on suspects that explain the residual about as well as the top one."""
    if len(suspects) < 2:
        return []
    top = suspects[0]
    notes = []
    for other in suspects[1:]:
        if other.caution and not top.caution:
            continue  # ranked apart on purpose (_demoted says why)
        p, _ = paired_test(errs[other.effect], errs[top.effect])
        lo, hi = sorted((top.rmse_heldout_deg, other.rmse_heldout_deg))
        rel = 100.0 * (hi - lo) / max(lo, 1e-300)
        if p < alpha and rel >= close_pct:
            continue
        a, b = top.effect.partition(":")[0], other.effect.partition(":")[0]
        how = TELL_APART.get(frozenset({a, b}))
        if how is None:
            how = (f"{top.effect} is revealed by {EFFECTS[a].protocol}; "
                   f"{other.effect} by {EFFECTS[b].protocol}")
        alike = "about equally" if rel < close_pct else f"alike within chance (paired p = {p:.2g})"
        notes.append(f"{top.effect} and {other.effect} explain the residual {alike} (held-out RMSE "
                     f"{top.rmse_heldout_deg:.3g} vs {other.rmse_heldout_deg:.3g} deg); to tell them apart: {how}")
    return notes
