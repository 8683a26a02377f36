"""Building blocks of `endocal validate`: axis data, regimes, residual tests, folds, paired test, Holm.

Signals are synthetic with known answers; tolerances are argued in comments.
"""

from __future__ import annotations

import shlex
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from endocal.shell import refit_command
from endocal.errors import ModelError
from endocal.models import HysteresisData
from endocal.runs.aligned import AlignedData
from endocal.validation.data import OTHER_CMD, axis_data, check_columns, load_candidates, prefix
from endocal.validation.folds import check_cv_data, fold_bounds, fold_split
from endocal.validation.identifiability import untestable_reason
from endocal.validation.paired import holm, paired_test
from endocal.validation.refit import Refit, refit_path
from endocal.validation.regimes import error_by_regime, hold_mask, reversal_distance_deg, turning_points
from endocal.validation.residuals import residual_tests

FS = 100.0


def _sine(duration_s=60.0, f_hz=0.1, amp=40.0):
    t = np.arange(int(duration_s * FS)) / FS
    return t, amp * np.sin(2 * np.pi * f_hz * t)


def _aligned(n=500, name="run"):
    t = np.arange(n) / FS
    df = pd.DataFrame({"t_s": t, "ap_cmd_deg": np.sin(t), "ap_meas_deg": 0.5 * np.sin(t),
                       "ml_cmd_deg": np.cos(t), "ml_meas_deg": 0.4 * np.cos(t),
                       "ap_current_ma": np.sin(2 * t), "sheath_wrap_deg": 180 + t, "contact_force_n": 0.0 * t})
    return AlignedData(df, ["ap", "ml"], Path(name), "0" * 64, {})


def test_axis_data_carries_the_other_axis_and_extras_and_concatenates_runs():
    a, b = _aligned(500, "a"), _aligned(300, "b")
    d = axis_data([a, b], "ap")
    assert d.n_samples == 800 and d.run_starts.tolist() == [0, 500]
    np.testing.assert_array_equal(d.extras[OTHER_CMD][:500], a.table["ml_cmd_deg"])
    np.testing.assert_array_equal(d.extras["ml_meas_deg"][500:], b.table["ml_meas_deg"])
    cands, constant = load_candidates(d, ["ap", "ml"])
    # the knob drive's own current responds to the bend (excluded); a constant column says nothing
    assert cands == ["sheath_wrap_deg"] and constant == ["contact_force_n"]
    with pytest.raises(ModelError, match="no axis 'lr'"):
        axis_data(a, "lr")
    with pytest.raises(ModelError, match="constant"):
        check_columns(d, ["contact_force_n"])
    with pytest.raises(ModelError, match="no column 'wrap'"):
        check_columns(d, ["wrap"])
    p = prefix(d, 600)
    assert p.n_samples == 600 and p.run_starts.tolist() == [0, 500]


def test_turning_points_and_distance_since_reversal():
    t, u = _sine(60.0, 0.1)
    d = HysteresisData(cmd_deg=u, t_s=t)
    turns = turning_points(d)
    # 6 cycles: a maximum and a minimum each (the last one, at 57.5 s, is left by 2.5 s), the
    # first at t = 2.5 s; the tolerance (1 % of
    # the span) only delays detection, the index is the extreme itself (within a sample).
    assert turns.size == 12
    np.testing.assert_allclose(t[turns], 2.5 + 5.0 * np.arange(12), atol=1.5 / FS)
    dist = reversal_distance_deg(d)
    assert np.all(np.isinf(dist[: turns[0]]))
    k = turns[3] + 100  # one second after a reversal of a 0.1 Hz, 40 deg sine: 40 (1 - cos(0.2 pi)) deg
    assert dist[k] == pytest.approx(40 * (1 - np.cos(2 * np.pi * 0.1 * 1.0)), rel=1e-3)


def test_holds_and_regimes_find_where_the_error_is():
    t = np.arange(3000) / FS
    u = np.where(t < 10, 30 * np.sin(2 * np.pi * 0.2 * t), 0.0)  # 10 s of motion then a 20 s hold
    d0 = HysteresisData(cmd_deg=u, t_s=t)
    hold = hold_mask(d0)
    assert hold[t > 10.01].all() and not hold[(t > 0.1) & (t < 9.9)].any()
    rng = np.random.default_rng(0)
    meas = u + 0.1 * rng.standard_normal(t.size)
    pred = u.copy()
    near = reversal_distance_deg(d0) < 0.1 * np.ptp(u)
    pred[near & ~hold] += 2.0  # the model is off by 2 deg right after reversals only
    d = HysteresisData(cmd_deg=u, meas_deg=meas, t_s=t)
    br = error_by_regime(d, pred)
    worst = br.worst(1)[0]
    assert worst.group == "motion" and worst.name.startswith("near reversal")
    # in that regime the error is the 2 deg offset plus 0.1 deg noise: RMSE sqrt(4 + 0.01)
    assert worst.metrics.rmse_deg == pytest.approx(np.sqrt(4.01), rel=0.02)
    hold_r = [r for r in br.regimes if r.name.startswith("hold")][0]
    assert hold_r.metrics.rmse_deg == pytest.approx(0.1, rel=0.1)  # noise only; 2000 samples
    assert {r.group for r in br.regimes} >= {"motion", "speed", "amplitude", "time"}


def test_residual_tests_white_noise_and_signatures():
    t, u = _sine(60.0, 0.1)
    d = HysteresisData(cmd_deg=u, t_s=t)
    rng = np.random.default_rng(1)
    white = residual_tests(d, rng.standard_normal(t.size))
    assert white.whiteness.white and not white.significant()
    # a residual that is the command 0.3 s ago, minus its present: a delay's signature
    lagged = np.interp(t - 0.3, t, u) - u + 0.05 * rng.standard_normal(t.size)
    r = residual_tests(d, lagged)
    assert not r.whiteness.white
    speed = {c.signal: c for c in r.cross}["speed"]
    # u(t - tau) - u(t) = -2 A sin(w tau / 2) cos(w (t - tau / 2)): the speed, delayed by tau / 2
    assert speed.significant and speed.corr_at_zero < -0.9 and 0.0 <= speed.lag_s <= 0.3


def test_folds_are_contiguous_rolling_origin_blocks():
    b = fold_bounds(1000, 5)
    assert b[0][0] == 500 and b[-1][1] == 1000
    assert all(b1 == a2 for (_, b1), (a2, _) in zip(b[:-1], b[1:]))  # contiguous, disjoint, in time order
    t, u = _sine(4.0, 0.1)  # less than one cycle: the first training half has no two reversals
    with pytest.raises(ModelError, match="too short"):
        check_cv_data(HysteresisData(cmd_deg=u, meas_deg=u, t_s=t), 5)
    with pytest.raises(ModelError, match="too short"):
        check_cv_data(HysteresisData(cmd_deg=u[:100], meas_deg=u[:100], t_s=t[:100]), 5)


def _ar1(rng, n, phi):
    e = np.empty(n)
    e[0] = rng.standard_normal()
    w = rng.standard_normal(n) * np.sqrt(1 - phi**2)
    for k in range(1, n):
        e[k] = phi * e[k - 1] + w[k]
    return e


def test_paired_test_is_calibrated_on_autocorrelated_errors_and_has_power():
    rng = np.random.default_rng(2)
    # Two equally good models whose errors are strongly autocorrelated (AR(1), phi = 0.98,
    # correlation time ~50 samples): the blocked test must reject at about its level. 200
    # replicates: the false-alarm count is Binomial(200, 0.05) under calibration, mean 10,
    # sd 3.1; 22 is ~4 sd above. A per-sample test would reject in most replicates.
    p = [paired_test(_ar1(rng, 3000, 0.98), _ar1(rng, 3000, 0.98))[0] for _ in range(200)]
    assert sum(x < 0.05 for x in p) <= 22
    e = _ar1(rng, 3000, 0.98)
    p_better, nb = paired_test(e, 0.5 * e + 0.1 * _ar1(rng, 3000, 0.98))
    assert p_better < 1e-3 and nb >= 10  # 3000 samples / (3 x ~50-sample correlation time)


def test_holm_adjustment():
    # sorted p: 0.005*4 = 0.02, 0.01*3 = 0.03, 0.03*2 = 0.06, then max(0.06, 0.04*1) = 0.06
    np.testing.assert_allclose(holm([0.01, 0.04, 0.03, 0.005]), [0.03, 0.06, 0.06, 0.02])


def test_refit_command_and_path():
    assert refit_path("models/m.json", "load:sheath_wrap_deg") == "models/m-load-sheath_wrap_deg.json"
    cmd = refit_command(Refit(("runs/a", "b.csv"), "ap", "bspline", ("delay",), "m-delay.json"))
    assert cmd == "endocal fit hysteresis runs/a b.csv --axis ap --model bspline --effects delay --out m-delay.json"
    # a path with a space stays one argument when the printed command is pasted into a shell
    cmd = refit_command(Refit(("lab data/run 1.csv",), "ap", "pi", ("load:wrap",), "m.json",
                              start_from="lab data/m 0.json"))
    assert shlex.split(cmd) == ["endocal", "fit", "hysteresis", "lab data/run 1.csv", "--axis", "ap", "--model", "pi",
                                "--effects", "load:wrap", "--start-from", "lab data/m 0.json", "--out", "m.json"]
    # the planes and the base's settings, in the order `fit hysteresis` documents them, values as --set reads them
    cmd = refit_command(Refit(("a",), None, "bspline", ("delay",), "m.json", settings={"n_knots": 3, "knots": "auto"},
                              planes_path="pl.json"))
    assert shlex.split(cmd)[3:] == ["a", "--model", "bspline", "--effects", "delay", "--planes", "pl.json",
                                    "--set", "n_knots=3", "--set", "knots=auto", "--out", "m.json"]


def test_folds_of_several_runs_take_the_same_share_of_every_run():
    # two runs of different kinds and lengths: every training block must hold some of each
    u = np.concatenate([np.sin(np.arange(400) / 10.0), 2 * np.sin(np.arange(200) / 3.0)])
    data = HysteresisData(cmd_deg=u, meas_deg=u + 1.0, t_s=np.arange(600) * 0.01, run_starts=np.array([0, 400]))
    bounds = fold_bounds(data.n_samples, 4)
    assert bounds[0] == (300, 375) and bounds[-1][1] == 600
    train, evaluate, held = fold_split(data, bounds[0])
    # half of each run trains (200 + 100), the next eighth of each is held out (50 + 25)
    assert train.n_samples == 300 and list(train.run_starts) == [0, 200]
    assert np.array_equal(train.cmd_deg, np.concatenate([u[:200], u[400:500]]))
    assert list(evaluate.run_starts) == [0, 250] and held.size == 75
    assert np.array_equal(evaluate.meas_deg[held], np.concatenate([u[200:250], u[500:525]]) + 1.0)
    # the last fold reaches the end of both runs; together the folds hold out each run's second half once
    helds = [evaluate.cmd_deg[h] for _, evaluate, h in (fold_split(data, b) for b in bounds)]
    assert sum(h.size for h in helds) == 300
    # one run: plain prefixes, as before
    one = prefix(data, 400)
    tr, ev, h = fold_split(one, (200, 250))
    assert tr.n_samples == 200 and ev.n_samples == 250 and np.array_equal(h, np.arange(200, 250))
    # runs that only reach the rest of their range later (a staircase up, then down) are laid
    # end to end instead: no fold may ask for commands its training block never saw
    stair = np.concatenate([np.linspace(0, 60, 150), np.linspace(60, -60, 150)])
    two = HysteresisData(cmd_deg=np.tile(stair, 2), meas_deg=np.tile(stair, 2), t_s=np.arange(600) * 0.01,
                         run_starts=np.array([0, 300]))
    tr, ev, h = fold_split(two, (300, 375))
    assert tr.n_samples == 300 and list(tr.run_starts) == [0] and np.array_equal(h, np.arange(300, 375))


@pytest.mark.parametrize("width_deg, speeds, covariates, named", [
    (0.85, (10.0, 28.0), [], {"delay", "rate"}),  # wider and 2.8x as fast: speed, not a changed condition
    (0.85, (10.0, 11.0), [], {"load"}),  # wider at the same speed: the friction changed between the records
    (-0.85, (10.0, 28.0), [], {"load"}),  # narrower though faster: no lag or speed friction does that
    (0.85, (10.0, 28.0), ["'wrap' is 180 in the estimation data and 360 here"], {"delay", "rate", "load"}),
])
def test_a_loop_that_changed_between_records_is_put_down_to_speed_only_when_the_speed_changed_alike(
        width_deg, speeds, covariates, named):
    from types import SimpleNamespace

    from endocal.validation.shift import RecordShift
    from endocal.validation.verdict import shift_pointers

    shift = RecordShift(rmse_deg=1.7, zero_deg=0.1, zero_rmse_deg=1.69, width_deg=width_deg, gain=0.96,
                        offset_deg=0.1, friction_rmse_deg=1.0)
    scan = SimpleNamespace(scheme="estimation/validation", baseline_rmse_heldout_deg=1.7, tested=[])
    ptrs = shift_pointers(shift, scan, covariates, speeds)
    assert {p.effect for p in ptrs} == named
    assert all(p.status == "untested" for p in ptrs)
    if "delay" in named:
        assert "2.8 times as fast" in next(p for p in ptrs if p.effect == "delay").evidence


@pytest.mark.parametrize("gain, named", [(0.96, True), (1.9, True), (0.45, False), (640_000.0, False)])
def test_a_slope_no_friction_change_makes_is_not_put_down_to_one(gain, named):
    # fitted on a record the model extrapolates, the shift's slope ran to +64 million %: no change
    # of friction between two records doubles or halves the loop's slope, so nothing is pointed at
    from types import SimpleNamespace

    from endocal.validation.shift import RecordShift
    from endocal.validation.verdict import shift_pointers

    shift = RecordShift(rmse_deg=1.7, zero_deg=0.1, zero_rmse_deg=1.69, width_deg=0.85, gain=gain,
                        offset_deg=0.1, friction_rmse_deg=1.0)
    scan = SimpleNamespace(scheme="estimation/validation", baseline_rmse_heldout_deg=1.7, tested=[])
    assert bool(shift_pointers(shift, scan, [], (10.0, 11.0))) == named


def _play_record(wrap_deg: np.ndarray, name: str) -> AlignedData:
    """A sine through a play whose half width grows with the wrap column (capstan friction)."""
    t, u = _sine(duration_s=wrap_deg.size / FS)
    y, p = np.empty_like(u), 0.0
    for k, (uk, w) in enumerate(zip(u, 2.0 + 0.02 * (wrap_deg - 180.0))):
        p = min(max(p, uk - w), uk + w)
        y[k] = 0.8 * p
    df = pd.DataFrame({"t_s": t, "ap_cmd_deg": u, "ap_meas_deg": y, "sheath_wrap_deg": wrap_deg})
    return AlignedData(df, ["ap"], Path(name), name[0] * 64, {})


@pytest.mark.parametrize("effects, note", [([], "no extra column varies in the estimation data (1 constant)"),
                                           (["load:sheath_wrap_deg"], None)])
def test_load_is_called_unidentifiable_only_when_no_covariate_varies_and_none_is_modelled(effects, note):
    from endocal.models import make_model
    from endocal.validation.offline import validate_offline

    n = 3000
    wrap = 180.0 + 90.0 * np.sin(2 * np.pi * np.arange(n) / n)
    est, val = _play_record(wrap, "est"), _play_record(wrap[::-1].copy(), "val")
    flat = _play_record(np.full(n, 180.0), "flat")
    train = [est] if effects else [flat]
    model = make_model("linear", effects, axis="ap").fit(axis_data(train, "ap"))
    res = validate_offline(model, [val], train=train, model_path="m.json")
    assert res.scan.untestable.get("load", "").startswith(note) if note else "load" not in res.scan.untestable


def test_a_suggestion_whose_own_parameter_ends_at_a_bound_carries_a_caution():
    """`pi` on a saturating Bouc-Wen loop (which its branches cannot draw) and a `delay` candidate.

    The delay runs to its lower bound, -0.5 s, a non-causal latency stretched to take up a loop
    shape: validate may still list what lowers the validation error, but says that its
    parameter sits at a bound (and ranks it after candidates that do not)."""
    from endocal.models import make_model
    from endocal.validation.offline import validate_offline
    from tests.test_models_pi import _bouc_wen

    def record(amp, period_s, seed):
        t = np.arange(0, period_s, 0.02)
        u = amp * np.sin(2 * np.pi * t / period_s)
        return HysteresisData(cmd_deg=u, meas_deg=_bouc_wen(u) + np.random.default_rng(seed).normal(0, 0.3, t.size),
                              t_s=t)

    est, val = record(60, 40, 1), record(45, 34, 2)
    model = make_model("pi", axis="ap").fit(est)
    res = validate_offline(model, val, train=est, model_path="m.json")
    # validate repeats what the fit said: this base found no loop it can shape
    assert any("no better than a straight line" in w for w in res.model["fit_warnings"]), res.model
    delay = next(s for s in res.scan.tested if s.effect == "delay")
    assert delay.caution.startswith("delay_s = -0.5 sits at its lower bound"), delay.caution
    order = [bool(s.caution) for s in res.scan.suspects]
    assert order == sorted(order)  # at-bound suggestions after the others


def test_a_start_no_history_explains_is_not_called_nothing_missing():
    # A one-sided sweep fitted from rest; the next acquisition starts at knob 0 with the tip still
    # 6 deg off (bent by a sweep the model never saw), the offset fading until the reversal. Its
    # error before the first reversal is many times the error after it and no start tried
    # predicts it: validate says so instead of "nothing is missing" (it said that, clean).
    from endocal.models import make_model
    from endocal.validation.offline import validate_offline

    rng = np.random.default_rng(0)
    u = 45 * 0.5 * (1 - np.cos(2 * np.pi * np.arange(2000) / 2000))  # 0 -> 45 -> 0 from rest

    def plant(u):
        z, y = 0.0, np.empty_like(u)
        for i, x in enumerate(u):
            z = min(max(z, x - 3.0), x + 3.0)
            y[i] = 0.8 * z
        return y

    def table(y, name):
        df = pd.DataFrame({"t_s": np.arange(u.size) / FS, "ap_cmd_deg": u,
                           "ap_meas_deg": y + 0.2 * rng.standard_normal(u.size)})
        return AlignedData(df, ["ap"], Path(name), name[0] * 64, {})

    est = table(plant(u), "est")
    bent = plant(u) - 6.0 * np.clip(1 - np.arange(u.size) / 1000, 0, 1)
    model = make_model("bspline", axis="ap").fit(axis_data([est], "ap"))
    res = validate_offline(model, [table(bent, "val")], train=[est], model_path="m.json")
    assert not res.clean and res.unexplained.startswith("the validation record's start is not explained"), \
        (res.unexplained, res.notes)
    assert any("No start tried predicts it" in n for n in res.notes)


def test_time_quarters_of_several_records_are_quarters_of_each():
    """Two records each restart the clock: a quarter of their concatenation spanned both, its
    times out of order ("quarter 4 (15..60 s)" printed before "quarter 2 (45..90 s)")."""
    from endocal.validation.regimes import regime_masks

    t = np.arange(400) * 0.1
    cmd = 30.0 * np.sin(2 * np.pi * t / 20.0)
    one = HysteresisData(cmd, meas_deg=cmd, t_s=t)
    two = HysteresisData(np.concatenate([cmd, cmd[:200]]), meas_deg=np.concatenate([cmd, cmd[:200]]),
                         t_s=np.concatenate([t, t[:200]]), run_starts=np.array([0, 400]))
    single = [(name, m) for kind, name, m in regime_masks(one) if kind == "time"]
    assert [name for name, _ in single] == ["quarter 1 (0..9.9 s)", "quarter 2 (10..19.9 s)", "quarter 3 (20..29.9 s)",
                                            "quarter 4 (30..39.9 s)"]
    both = [(name, m) for kind, name, m in regime_masks(two) if kind == "time"]
    assert [name for name, _ in both] == [f"quarter {q} of each of the 2 records" for q in (1, 2, 3, 4)]
    # each quarter holds a quarter of every record: 100 + 50 samples
    assert all(m.sum() == 150 and m[:400].sum() == 100 for _, m in both)


def test_creep_check_looks_for_the_move_before_a_hold_on_its_own_record_clock():
    # Issue 27.4: records laid end to end restart their clocks, so the concatenated t_s is not
    # sorted; searching it for "2 s before the hold" landed in the next record (an empty slice,
    # a traceback). A short record that stops after a move, then a long one that never holds.
    t1, t2 = np.arange(1000) / FS, np.arange(10000) / FS  # 10 s, then 100 s
    u1 = 40 * np.sin(2 * np.pi * 0.2 * np.minimum(t1, 8.0))  # moves, then holds from 8 s
    u2 = 40 * np.sin(2 * np.pi * 0.1 * t2)
    runs = [HysteresisData(cmd_deg=u, meas_deg=u, t_s=t) for u, t in ((u1, t1), (u2, t2))]

    def creep_reason(data):  # what creep declares it needs to be told from a wider loop (Creep.requires)
        return untestable_reason("creep", data, to=("fit", "test"))

    assert creep_reason(HysteresisData.from_runs(runs)) is None  # the hold after the first record's move
    assert creep_reason(HysteresisData.from_runs(runs[::-1])) is None  # in either order
    # without that hold there is none to see creep in; a record that starts at rest is no hold after a move
    still_start = np.where(t2 < 5.0, 0.0, u2)
    moving = [HysteresisData(cmd_deg=u, meas_deg=u, t_s=t) for u, t in ((u2, t2), (still_start, t2))]
    assert creep_reason(HysteresisData.from_runs(moving)).startswith("no holds: creep cannot be identified")
