"""The closed loop, the way a user works (issue 27): validate, refit what it suggests, and record what
`validate --next` asks for when it can suggest nothing more, until every hidden effect is found.

One recipe for every case; nothing is picked per case:

- the simulator of tests/test_validation_hidden.py with one effect hidden (its sections, its
  strengths), the default rig lag present (servo 2 x 30 ms, tracker 15 ms), seed 0;
- estimation data: the duodenoscope paper's damped sine and a chirp of 50 deg; validation data: a
  band-limited random run of 60 deg (the records of tests/test_validation_user_style.py);
- the starting model: the first of ``STARTS`` that does not hold the hidden effect. A B-spline
  carrying `delay` for the rig's lag is the base of every case but two: the `delay` case (the base
  holds the effect: a B-spline without it, next in the order) and the `envelope` case (the
  B-spline's branch shapes are free functions of the command, so any static stiffening is in the
  base, as tests/test_validation_user_style.py shows: the paper's `pi` with `delay`, next);
- the loop: validate (estimation/validation scheme, the scan's sample budget of the hidden-effect
  tests); when it suggests an effect, run its printed refit (:func:`printed_refit`: on the
  estimation data, starting from the model, with the candidate's start values); when it suggests none but
  `validate --next` finds something to test, write that protocol, record it twice on the simulator
  through `excite`'s own code (`prepare_backend`, `run_excitation`; a condition it asks for set to
  2/3 of the value the records hold), add the first recording to the estimation data, refit the
  model's structure, and validate on the second, a fresh recording of the same plan; when the plan
  asks for a condition, the first recording is also made at the value the records hold (--next's
  third excite command: the same motion at two values of the condition, issue 32) and added to the
  estimation data; at most two added recordings; the loop ends when --next finds nothing to test or
  two recordings were added and nothing is suggested.
- foreign plants (issue 31 part 4, ``FOREIGN``): the same recipe on plants whose law is not the
  catalogue's (friction thresholds growing linearly with knob speed, a creep with two time
  constants, a dead band off neutral); the loop must name the effect's family. Measured
  2026-11-28 (the whole file, 58 min of a shared core, seed 0, the coupling term with the other
  bend's lag): `rate` named on the linear-law plant (2.07 -> 0.474 deg, clean at the end), `creep`
  on the two-time-constant plant (1.94 -> 0.74 deg); on the off-centre band (+12 deg) the loop
  refits `envelope`, `deadzone`, `coupling`, `load:sheath_wrap_deg` (recorded at 180 and 120 deg,
  the same motion), `tension`, two recordings added, 1.29 -> 0.597 deg, the end structure without
  `deadzone` 0.600 (`tension` is not in the plant: a false discovery; before the scan asked an
  additive term to earn its gain itself, `drift` was added too, to 0.504 deg). Run again 2026-12-06
  with the printed refits: `rate` and `creep` as before (2.07 -> 0.474, 1.94 -> 0.74 deg); the
  off-centre band adds `creep` in `tension`'s place (also not in the plant), 1.52 -> 0.447 deg. The foreign rate plant validated once from a B-spline without the rig's lag
  (`test_a_foreign_rate_plant_is_named_rate_not_delay`): `rate` -17.8 %, `delay` -16.4 %,
  `creep` -14.6 % (held-out RMSE 0.415 deg, noise 0.33); the look-alikes settled: the records
  prefer `rate` over `delay` (0.341 vs 0.347 deg, p = 0.00015), and `delay` after `rate` adds
  nothing (p = 1).

The bars (issue 27, "How good"): the hidden effect named, by a suggestion refitted in the loop, in 8
of 8; the validation RMSE halved from the loop's start in at least 7 of 8; the control ends with
nothing missing. "Halved from the loop's start" compares the model the loop started from with the
one it ended with on the same records, the loop's last: the starting structure refitted on the
final estimation data and scored on the final validation record (`validate END --compare START`),
since a record the loop added (both knobs moving, say) is where the start model's error shows. That
comparison also credits what the loop found besides the hidden effect (the cross-talk of the two
bends through eq. 1 that `coupling` takes up, which the control finds too); the hidden effect's own
share (the final model without it, refitted on the same data) is recorded beside it (``LoopResult``).

Measured (2026-12-08, seed 0, the fits on their compressed form (endocal.models.lsq), each refit as `validate`
printed it: :func:`printed_refit`; RMSE in deg on the loop's last records, start structure -> end; "own share":
the end structure without the hidden effect -> with it):

=========  ==============  =============================================  =====  ===================  ==================
hidden     start           refitted in the loop, in order                 added  start -> end         own share
=========  ==============  =============================================  =====  ===================  ==================
drift      bspline+delay   drift, coupling, load                          2      11.6 -> 0.41 (-97%)  14.6 -> 0.41 (-97%)
delay      bspline         delay, coupling, load, deadzone                2      9.84 -> 0.40 (-96%)  9.36 -> 0.40 (-96%)
rate       bspline+delay   coupling, load, rate                           1      3.69 -> 0.49 (-87%)  0.56 -> 0.49 (-13%)
creep      bspline+delay   creep, coupling, load                          2      4.46 -> 0.39 (-91%)  3.06 -> 0.39 (-87%)
load       bspline+delay   load, coupling                                 2      1.89 -> 0.40 (-79%)  0.94 -> 0.40 (-57%)
deadzone   bspline+delay   deadzone, coupling, load                       2      1.67 -> 0.41 (-76%)  0.63 -> 0.41 (-35%)
envelope   pi+delay        envelope, tension, coupling, load              2      2.17 -> 0.55 (-75%)  1.21 -> 0.55 (-55%)
coupling   bspline+delay   coupling, load                                 2      2.37 -> 0.48 (-80%)  2.04 -> 0.48 (-77%)
(control)  bspline+delay   coupling, load                                 2      1.89 -> 0.42 (-78%)  -
=========  ==============  =============================================  =====  ===================  ==================

On 2026-12-06 (commit 41e998c, the plain solver) the loops named and added the same, but for three: `delay` added
`creep` where it now adds `deadzone` (neither is in the plant), `rate` added two recordings (2.68 -> 0.97 deg,
own share 1.63 -> 0.97) and `envelope` added `deadzone` too (a false discovery, gone since 2026-12-07).

Until 2026-12-05 the loop refitted from the model alone, without the candidate's start values the printed
command carries (`--start-value`). Run as printed, the `envelope` case adds `deadzone` too (the plant has no
slack): a false discovery the old recipe did not make. The other cases name and add as before, and end within
0.01 deg of it. The control ends with nothing missing (1.89 -> 0.419 deg, its validations 0.335, 3.68, 0.619,
0.439, 0.419; 2026-12-07, with one process and with two, at this session's code and at abd3083): the record of
2026-12-06 that had it end pointing at `rate` (-4 %, p = 0.061, after a `load` refit at 0.428 deg) does not
reproduce on the committed code.

`load` is the sheath's wrap: the first --next asks for it (the records hold it constant), the
recipe sets it to 120 deg, and the simulator's friction follows, so every loop finds it. `coupling`
is named in the control too: with both knobs moving, eq. 1 reads this axis from a tip both bends put
there through the deviated half-planes (the default probe's), which the term takes up. `rate` is
found on the second recording, a speed ladder alone up to the probe's limits (the first, whose both-
knob segment the start model misses by 1 deg, leaves it under the 10 % bar); its own share stays at
-38 %: the catalog term, fitted beside the carried `delay`, takes up part of the simulator's speed-
dependent capstan friction (-20 % of the ladder's error on its own).

Expensive (a loop records and validates up to seven times; 50-58 min of one core for the file on
2026-11-28): marked ``slow``, outside the 10-minute suite; run it with ``make test-slow`` (or
``pytest -m slow tests/test_validation_closed_loop.py``).
"""

from __future__ import annotations

import functools
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

from endocal.backends.sim import SimBackend
from endocal.excite import prepare_backend, run_excitation
from endocal.fitting import fit_hysteresis
from endocal.models import make_model
from endocal.probe import PRESETS
from endocal.protocols import read_protocol_file
from endocal.runs.aligned import load_aligned
from endocal.sim import SimConfig
from endocal.validation.data import axis_data
from endocal.validation.next_experiment import NothingSuspectedError, design_next
from endocal.validation.offline import validate_offline
from endocal.validation.predict import predict_errors
from endocal.validation.structure import split_fit
from tests.test_validation_hidden import NO_SLACK, simulate
from tests.test_validation_user_style import HIDDEN

pytestmark = pytest.mark.slow

TEE = PRESETS["tee"]
#: Starting models in a fixed order: (base, effects).
STARTS = [("bspline", ["delay"]), ("bspline", []), ("pi", ["delay"])]
#: Effects a base holds without the term: the B-spline's free branch shapes take up any static shape.
HELD = {"bspline": {"envelope"}}
SCAN_SAMPLES = 3000  # the scan's decimation budget of tests/test_validation_hidden.py
MAX_ADDED = 2
#: A condition --next asks for is set to this share of the value the records hold (one rule for all).
CONDITION_SHARE = 2.0 / 3.0
#: Plants whose law is not the catalogue's (issue 31 part 4), by the family the loop must name: friction
#: thresholds that grow linearly with knob speed, x (1 + 0.012 |v|), v in deg/s (the catalogue's rate is the
#: capstan's exponential); a relaxation with two time constants, 1 s and 12 s (the catalogue's creep has
#: one); a dead band centred at +12 deg of knob (the simulator's slack is centred at 0).
FOREIGN = {
    "rate-linear": ("rate", {"rate": {"enabled": True, "gain_s_per_deg": 0.012, "law": "linear"}}),
    "creep-two-taus": ("creep", {"creep": {"enabled": True, "fraction": 0.15, "time_constant_s": 1.0,
                                           "fraction2": 0.15, "time_constant2_s": 12.0}}),
    "deadzone-off-centre": ("deadzone", {"deadzone": {"enabled": True, "center_deg": 12.0}}),
}


def family(case: str | None) -> str | None:
    """The catalogue effect a case hides (a foreign plant's family)."""
    return FOREIGN[case][0] if case in FOREIGN else case


def sections(case: str | None) -> dict:
    return FOREIGN[case][1] if case in FOREIGN else HIDDEN.get(case, {})


def start_for(hidden: str | None) -> tuple[str, list[str]]:
    """The first start that does not hold the hidden effect."""
    return next((b, e) for b, e in STARTS if hidden not in e and hidden not in HELD.get(b, set()))


@dataclass
class LoopResult:
    """What one closed loop did.

    Attributes
    ----------
    start : str
        The starting model (``base+effects``).
    named : list of str
        Effects refitted in the loop, in order.
    added : int
        Recordings added (each recorded twice: once to fit on, once to validate on).
    history_deg : list of float
        Validation RMSE of the model as it stands at each validate (on that step's records).
    start_deg, end_deg : float
        The starting and the final structure on the loop's last records (both refitted on its final
        estimation data, scored on its final validation record).
    without_hidden_deg : float or None
        The final structure without the hidden effect, on the same records (None: not named).
    clean : bool
        The last validate finds nothing missing (no suggestion, no pointer, nothing unexplained).
    next_said : str
        What the last `--next` said when it found nothing to test (empty otherwise).
    """

    start: str
    named: list = field(default_factory=list)
    added: int = 0
    history_deg: list = field(default_factory=list)
    start_deg: float = float("nan")
    end_deg: float = float("nan")
    without_hidden_deg: float | None = None
    clean: bool = False
    next_said: str = ""

    @property
    def fall_pct(self) -> float:
        return 100.0 * (1.0 - self.end_deg / self.start_deg)


def _record(cfg: SimConfig, path: Path, seed: int, out: Path, earlier: bool = False):
    """Run a --next protocol as `excite` does, on the simulator, and load its aligned table (``earlier``: a
    condition at the value the records hold, as --next's third excite command asks)."""
    proto = read_protocol_file(path)
    share = 1.0 if earlier else CONDITION_SHARE
    values = {k: share * c["recorded"][0] if c["recorded"] else (2.0 if earlier else 1.0)
              for k, c in proto.conditions.items()}
    proto = proto.with_overrides(values)
    proto.check_conditions()
    traj = proto.trajectory(TEE, seed=seed)
    traj.check_limits(TEE)
    backend, rec = prepare_backend(SimBackend(cfg, TEE, seed), proto, TEE)
    run_excitation(traj, backend, TEE, out, protocol_info={**proto.to_dict(), **rec}, seed=seed)
    return load_aligned(out)


def record_next(cfg: SimConfig, model, res, est: list, val: list, tmp: Path, k: int) -> tuple[list, list]:
    """The loop's k-th recording: the protocol `validate --next` writes for ``res``, recorded as it asks (once
    to fit, and for a condition once more at the earlier value; once to validate on). Returns the estimation
    records with the new ones, and the new validation record. Raises NothingSuspectedError."""
    plan = design_next(model, res, axis_data(est, "ap"), axis_data(val, "ap"), TEE, model_path=str(tmp / "m.json"))
    path = plan.write(tmp / f"next-{k}.toml")
    est = est + [_record(cfg, path, 100 + k, tmp / f"fit-{k}")]
    if plan.conditions:  # the same motion at the earlier value of the condition (issue 32)
        est = est + [_record(cfg, path, 100 + k, tmp / f"fit-{k}-earlier", earlier=True)]
    return est, [_record(cfg, path, 200 + k, tmp / f"val-{k}")]


def follow(res, base: str, model, cfg: SimConfig, est: list, val: list, tmp: Path, out):
    """One turn of the loop after a validate (``res``): refit with its first suggestion; else record what
    `--next` asks (at most MAX_ADDED times, :func:`record_next`) and refit on it. Returns ``(model, est,
    val)``, or None when the loop ends (``out.next_said`` says why when `--next` said it); counts in ``out``."""
    if res.suspects:
        out.named.append(res.suspects[0].effect)
        return printed_refit(res.suspects[0].refit, model, est), est, val
    if out.added == MAX_ADDED:
        return None
    try:
        est, val = record_next(cfg, model, res, est, val, tmp, out.added + 1)
    except NothingSuspectedError as exc:
        out.next_said = str(exc)
        return None
    out.added += 1
    return _refit(base, [e.label for e in model.effects_], model, est), est, val


def _refit(base: str, effects: list[str], start, est):
    """The model's structure refitted on the estimation data after a recording, from the model (``fit hysteresis
    ... --start-from M.json``)."""
    return make_model(base, effects, axis="ap").fit_from(start, axis_data(est, "ap"))


def printed_refit(refit, start, est):
    """What the refit command ``validate`` printed runs (its base, effects, ``--set`` settings, ``--start-from`` the
    validated model, its ``--start-value`` options), on the estimation data in memory: the fit the user gets."""
    return fit_hysteresis(est, "ap", refit.base, list(refit.effects), start_from=start,
                          start_values=refit.start_values, **refit.settings).model


@functools.lru_cache(maxsize=None)
def run_loop(case: str | None) -> LoopResult:
    """The recipe of the module docstring, for one hidden effect or foreign plant (None: the control)."""
    hidden = family(case)
    cfg = SimConfig.default().replace(**NO_SLACK).replace(**sections(case))
    est = [simulate(cfg, "damped-sine", {}, seed=0)[0], simulate(cfg, "chirp", {"amplitude_deg": 50.0}, seed=0)[0]]
    val = [simulate(cfg, "random", {"amplitude_deg": 60.0}, seed=0)[0]]
    base, effects = start_for(hidden)
    model = start = make_model(base, effects, axis="ap").fit(axis_data(est, "ap"))
    out = LoopResult(start="+".join([base, *effects]))
    tmp = Path(tempfile.mkdtemp(prefix=f"loop-{case}-"))
    res = None
    for _ in range(12):  # a bound the loop never reaches: at most two recordings and a refit per effect
        # each validate also scores the start model on its records (`--compare`): the last one's comparison is the
        # loop's start -> end (one fit more per validate, where scoring the end again would take a whole scan)
        res = validate_offline(model, val, train=est, model_path=str(tmp / "m.json"), max_scan_samples=SCAN_SAMPLES,
                               compare=start)
        out.history_deg.append(res.scan.baseline_rmse_heldout_deg)
        step = follow(res, base, model, cfg, est, val, tmp, out)
        if step is None:
            break
        model, est, val = step
    else:
        raise AssertionError(f"the loop on {case or 'the control'} did not end in 12 turns: {out.history_deg}")
    out.clean = bool(res.clean)
    out.start_deg, out.end_deg = res.compare.old_heldout_rmse_deg, res.compare.new_heldout_rmse_deg
    hidden_label = next((e.label for e in model.effects_ if e.label.partition(":")[0] == hidden), None)
    if hidden_label is not None:
        rest = [e.label for e in model.effects_ if e.label != hidden_label]
        err = predict_errors(split_fit(model, rest, axis_data(est, "ap")), axis_data(val, "ap"))
        out.without_hidden_deg = float(np.sqrt(np.mean(err**2)))
    return out


def _say(case, loop: LoopResult) -> None:
    """The loop's numbers, for the docstring's table (shown with ``pytest -s``)."""
    print(f"\nLOOP {case}: start {loop.start}, named {loop.named}, added {loop.added}, history "
          f"{[round(h, 3) for h in loop.history_deg]}, start -> end {loop.start_deg:.3g} -> {loop.end_deg:.3g} deg, "
          f"own share {loop.without_hidden_deg}, clean {loop.clean}")


def _named(hidden: str, loop: LoopResult) -> bool:
    return hidden in [e.partition(":")[0] for e in loop.named]


@pytest.mark.parametrize("hidden", list(HIDDEN))
def test_the_hidden_effect_is_named_by_a_refitted_suggestion(hidden):
    loop = run_loop(hidden)
    _say(hidden, loop)
    assert loop.added <= MAX_ADDED
    assert _named(hidden, loop), (loop.start, loop.named, loop.added, loop.history_deg, loop.next_said)


@pytest.mark.parametrize("hidden", list(HIDDEN))
def test_the_loop_halves_the_validation_rmse_from_its_start(hidden):
    loop = run_loop(hidden)
    assert loop.end_deg <= 0.5 * loop.start_deg, (loop.start, loop.named, loop.start_deg, loop.end_deg)


def test_the_bars_of_the_issue():
    """8 of 8 named, at least 7 of 8 halved, at most two added recordings each."""
    loops = {h: run_loop(h) for h in HIDDEN}
    named = [h for h, lp in loops.items() if _named(h, lp)]
    halved = [h for h, lp in loops.items() if lp.end_deg <= 0.5 * lp.start_deg]
    assert all(lp.added <= MAX_ADDED for lp in loops.values())
    assert len(named) == 8 and len(halved) >= 7, (named, halved)


#: What the control plant has that the start model lacks: eq. 1's cross-talk of the two bends and the sheath wrap's
#: friction (the module docstring).
CONTROL_HAS = {"coupling", "load:sheath_wrap_deg"}


def test_the_control_ends_with_nothing_missing():
    loop = run_loop(None)
    _say(None, loop)
    assert loop.added <= MAX_ADDED
    assert loop.clean, (loop.named, loop.history_deg)


def test_the_control_adds_nothing_the_plant_lacks():
    loop = run_loop(None)
    assert loop.added <= MAX_ADDED
    assert set(loop.named) <= CONTROL_HAS, (loop.named, loop.history_deg)


@pytest.mark.parametrize("case", list(FOREIGN))
def test_a_foreign_plant_is_named_by_its_family(case):
    """Issue 31 part 4: a plant whose law is not the catalogue's; the loop names the effect's family."""
    loop = run_loop(case)
    _say(case, loop)
    assert loop.added <= MAX_ADDED
    assert _named(family(case), loop), (case, loop.start, loop.named, loop.added, loop.history_deg, loop.next_said)


def test_a_foreign_rate_plant_is_named_rate_not_delay():
    """Issue 31 part 4: friction thresholds x (1 + 0.012 |v|) (v in deg/s), no servo or tracker lag, recorded as a
    user records; the start model (a B-spline) lacks both look-alikes. A lag and speed-dependent friction both
    widen the loop with speed, so the scan may rank `delay` first; the chirp in the estimation records spans
    speeds, so validate settles the pair: it scores `rate` in `delay`'s place and after it, and the records
    prefer `rate`, which is suggested first."""
    from tests.test_validation_hidden import NO_LAG

    cfg = SimConfig.default().replace(**NO_SLACK).replace(**NO_LAG).replace(**FOREIGN["rate-linear"][1])
    est = [simulate(cfg, "damped-sine", {}, seed=0)[0], simulate(cfg, "chirp", {"amplitude_deg": 50.0}, seed=0)[0]]
    val = [simulate(cfg, "random", {"amplitude_deg": 60.0}, seed=0)[0]]
    model = make_model("bspline", axis="ap").fit(axis_data(est, "ap"))
    res = validate_offline(model, val, train=est, model_path="m.json", max_scan_samples=SCAN_SAMPLES)
    ranked = [(s.effect, round(s.gain_pct, 1)) for s in res.scan.tested]
    assert res.suspects and res.suspects[0].effect == "rate", (ranked, res.scan.notes)
    pair = [x for x in res.scan.lookalikes if {x.suggested, x.lookalike} == {"rate", "delay"}]
    if pair:  # delay ranked first by its gain: the settlement named rate, with p
        assert pair[0].separated and pair[0].preferred == "rate" and pair[0].p_value < 0.05, pair[0]
