"""Every hidden effect recorded the way a user records (issue 12, "simulated, less shaped").

The hidden effects are those of tests/test_validation_hidden.py, defined there (same sections,
same strengths), but nothing is picked per case: the default simulated probe with its servo
and tracker lag, one seed, estimation on the duodenoscope paper's damped sine plus a chirp,
validation on a band-limited random run, and the thesis's model, a B-spline, carrying `delay`
as a user of this rig does for its known lag (without it in the delay case, where the delay is
what is hidden). The estimation/validation scheme must name the hidden effect first, and the
refit with it must cut the validation RMSE by at least 50 %. A control with nothing hidden
must list nothing.

Where that fails, the case is a strict xfail with the reason measured: a fix shows up as an
unexpected pass. The gaps are physics this recording cannot show or this model already has,
not tuning (numbers: seed 0, noise floor 0.33 deg):
- `envelope`: the default probe stiffens (it is on in the control too), and the B-spline's free
  branch shapes take up any static shape, so nothing is missing (0.335 deg);
- `coupling`: the damped sine, the chirp and the random run move one knob; the other bend never
  changes, so nothing couples (0.339 deg against its 0.333 deg floor);
- `rate` (friction x(1 + 0.02 s/deg |knob speed|)): the random run stays below 0.2 Hz, where
  the extra friction leaves 0.41 deg, at most -19 % to find, and the linear part of a
  speed-proportional lag is the `delay` the model carries (scan: -8 %, not significant);
- `load`: named first, the refit cuts -46 %.

Another base does not close the gaps: `pi` with `tension` and `delay`, on a probe whose
stiffening is switched off so that the envelope can be hidden, names 6 of 8 (envelope found,
-57 %) and cuts 5 of 8 (load -30 %), but its control lists `envelope` (-14 %: the play bank
does not take the capstan plant's static shape). Meeting 7 of 8 would take a protocol moving both knobs
and a faster random run, i.e. a recording picked for the effect.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest

from endocal.models import make_model
from endocal.sim import SimConfig
from endocal.validation.data import axis_data
from endocal.validation.offline import validate_offline
from endocal.validation.predict import predict_extrapolated
from tests.test_validation_hidden import CASES, NO_SLACK, simulate

#: the hidden set's sections without its per-case lag removal: the rig's lag stays in every case
HIDDEN = {h: {k: v for k, v in case[0].items() if k not in ("motor", "tracker")} for h, case in CASES.items()}
NAME_GAPS = {
    "envelope": "the default probe's stiffening is in the control too, and the B-spline absorbs any static shape",
    "coupling": "single-knob protocols: the other bend never changes, so coupling cannot show",
    "rate": "below 0.2 Hz the extra friction leaves < 20 % to find, and its linear part is the carried delay",
}
CUT_GAPS = {**NAME_GAPS, "load": "the refit with the named load term cuts -46 %"}
SCAN_SAMPLES = 3000  # validate's decimation budget for the candidates' fits, as in test_validation_hidden


@functools.lru_cache(maxsize=None)
def _fitted(hidden: str | None):
    """The records of a case and the thesis's model fitted on its estimation records: (estimation
    records, their axis data, the validation record, the model's effects, its noise floor, the model)."""
    cfg = SimConfig.default().replace(**NO_SLACK).replace(**HIDDEN.get(hidden, {}))
    est = [simulate(cfg, "damped-sine", {}, seed=0)[0], simulate(cfg, "chirp", {"amplitude_deg": 50.0}, seed=0)[0]]
    val, noise = simulate(cfg, "random", {"amplitude_deg": 60.0}, seed=0)
    effects = [] if hidden == "delay" else ["delay"]
    train = axis_data(est, "ap")
    return est, train, val, effects, noise, make_model("bspline", effects, axis="ap").fit(train)


@functools.lru_cache(maxsize=None)
def _case(hidden: str | None):
    est, train, val, effects, noise, model = _fitted(hidden)
    res = validate_offline(model, [val], train=est, model_path="m.json", max_scan_samples=SCAN_SAMPLES)
    return res, train, val, effects, noise


def _params(gaps):
    # raises=AssertionError: the expected miss is an assertion that fails; a crash is not one
    return [pytest.param(h, marks=pytest.mark.xfail(strict=True, raises=AssertionError, reason=gaps[h]))
            if h in gaps else h for h in HIDDEN]


@pytest.mark.parametrize("hidden", _params(NAME_GAPS))
def test_the_hidden_effect_is_named_first(hidden):
    res = _case(hidden)[0]
    assert res.scan.scheme == "estimation/validation"
    first = res.scan.suspects[0].effect.split(":")[0] if res.scan.suspects else None
    assert first == hidden, [(s.effect, round(s.gain_pct, 1)) for s in res.scan.tested]


@pytest.mark.parametrize("hidden", _params(CUT_GAPS))
def test_the_refit_halves_the_validation_error(hidden):
    res, train, val, effects, noise = _case(hidden)
    assert res.scan.suspects, "nothing named"
    refit = make_model("bspline", effects + [res.scan.suspects[0].effect], axis="ap").fit(train)
    v = axis_data([val], "ap")
    after = float(np.sqrt(np.mean((predict_extrapolated(refit, v)[0] - v.meas_deg) ** 2)))  # as validate scores it
    before = res.scan.baseline_rmse_heldout_deg
    assert after <= 0.5 * before, (before, after, noise)


def test_control_with_nothing_hidden_lists_nothing():
    res, _, _, _, noise = _case(None)
    assert res.scan.suspects == (), [(s.effect, round(s.gain_pct, 1), s.p_value) for s in res.scan.suspects]
    # the model is right for this probe: its validation error is the tracker noise (x1.1 for
    # the servo lag that `delay` approximates as a pure latency; measured 1.01x)
    assert res.scan.baseline_rmse_heldout_deg <= 1.1 * noise


@pytest.mark.parametrize("hidden", ["rate", "coupling", "envelope"])
def test_three_hidden_effects_leave_too_little_to_halve(hidden):
    """Why the bar of 7 in 8 is out of reach on these recordings, whatever the diagnosis or the base.

    A refit scored on the validation run cannot beat its tracker noise, so halving the error
    needs a model error at least twice that floor before the refit. Rate (1.24x: the random
    run is slow), coupling (1.02x: one knob moves) and, with the B-spline, envelope (1.02x: the
    hidden stiffening is the default probe's, so this is the control's record, whose shape the
    free branches take up) sit below it, so at most 5 of 8 can halve with this model. `pi` +
    `tension` + `delay` on a probe that does not stiffen (measured by hand, seed 0) adds the
    envelope (0.99 deg, -57 %) but leaves rate (0.53 deg) and coupling (0.49) under twice its
    own floor (0.43): 6 of 8 at most. Should a change of the simulator or the protocols lift
    one of them over the floor, this fails: try the bar again.
    """
    res, _, _, _, noise = _case(hidden)
    assert res.scan.baseline_rmse_heldout_deg < 2.0 * noise, (res.scan.baseline_rmse_heldout_deg, noise)


def test_a_fit_from_scratch_is_never_worse_than_the_model_without_the_added_effect():
    """A user's own refit (no --start-from) of the control with `deadzone` added on its estimation data.

    The model with `deadzone` nests the one without (no slack is a deadzone of zero width), so
    its least-squares fit must reach that model's training error. The start search tries each
    effect's candidates in chain order; it used to restart the delay at its raw candidate (0.4 s,
    which had refined to 0.08 s) while trying the deadzone's, and every deadzone start then
    looked worse than a wrong one: 0.437 deg against 0.344 deg without the term.
    """
    _, train, _, effects, _, control = _fitted(None)
    without = control.fit_report_.rmse_deg  # the control's model: this fit from scratch without the term
    with_dz = make_model("bspline", effects + ["deadzone"], axis="ap").fit(train).fit_report_.rmse_deg
    assert with_dz <= without * (1 + 1e-3), (without, with_dz)
