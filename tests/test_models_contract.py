"""Contract run against every model and model+effect: fit, predict, inverse, stream, save, load."""

import json

import numpy as np
import pytest

from endocal.errors import ModelError
from endocal.models import BASES, HysteresisData, load_model, make_model, save_model
from tests._models_signals import PAPER_TABLE1, damped_sine

CASES = [(b, e) for b in ("linear", "bspline", "pi", "bouc-wen", "dahl") for e in ((), ("envelope",))]


@pytest.fixture(scope="module")
def data():
    rng = np.random.default_rng(11)
    t, u = damped_sine(dt_s=0.05)
    truth = make_model("pi", ["envelope"]).set_parameters(PAPER_TABLE1)
    y = truth.predict(u) + 0.3 * rng.standard_normal(u.size)
    # two runs fitted together: the second a smaller sine
    t2 = np.arange(0, 40, 0.05)
    u2 = 30 * np.sin(2 * np.pi * 0.1 * t2)
    y2 = truth.predict(u2) + 0.3 * rng.standard_normal(u2.size)
    return [HysteresisData(cmd_deg=u, meas_deg=y, t_s=t), HysteresisData(cmd_deg=u2, meas_deg=y2, t_s=t2)], truth


@pytest.fixture(scope="module")
def fitted(data):
    runs, _ = data
    return {case: make_model(case[0], list(case[1]), axis="lr").fit(runs) for case in CASES}


@pytest.mark.parametrize("case", CASES, ids=lambda c: "+".join((c[0],) + c[1]))
def test_contract(case, data, fitted, tmp_path):
    runs, truth = data
    m = fitted[case]
    # fitted attributes and report
    assert set(m.params_) == set(m.parameter_names())
    assert m.fit_report_.n_runs == 2 and m.fit_report_.nfev > 0
    assert len(m.training_data_) == 2
    # predictions: per run when given a list; every model explains most of the motion
    # (a classic PI lacks the dead band of the modified-PI data, so no tighter common bound)
    pred = m.predict([r.cmd_deg for r in runs])
    assert isinstance(pred, list) and len(pred) == 2
    rmse = np.sqrt(np.mean(np.concatenate([p - r.meas_deg for p, r in zip(pred, runs)]) ** 2))
    if not m.fit_report_.estimated_starts:  # a run fitted from an estimated start is scored from it (models.start)
        assert rmse == pytest.approx(m.fit_report_.rmse_deg, rel=1e-9)
    assert rmse < 0.15 * np.std(np.concatenate([r.meas_deg for r in runs]))
    # inverse: predict(inverse(y)) == y for a reachable y (the model's own output of a smaller motion)
    y_des = m.predict(0.8 * runs[0].cmd_deg)
    try:
        u = m.inverse(y_des)
    except ModelError as exc:
        # a base whose fitted law cannot be inverted says so in one line naming it, and refuses to compensate
        # (a smooth friction base whose tip moves back after a reversal on this pinched loop)
        assert not m.return_point_memory and case[0] in str(exc) and "\n" not in str(exc)
        assert "compensation refused" in str(exc)
        with pytest.raises(ModelError, match="compensation refused"):
            m.compensator()
        u = None
    if u is not None:
        assert np.max(np.abs(m.predict(u) - y_des)) < 1e-8
        # a held target holds the command (test_a_held_target_holds_the_command for a flat band)
        y_hold = np.concatenate([y_des[:300], np.full(200, y_des[299])])
        assert np.ptp(m.inverse(y_hold)[300:]) < 1e-9
        # the streaming compensator gives the batch inverse sample by sample
        comp = m.compensator()
        streamed = np.array([comp.step(v) for v in y_des[:400]])
        assert np.max(np.abs(streamed - u[:400])) < 1e-9
    # save / load: exact round trip of predictions and inverse
    path = tmp_path / "model.json"
    save_model(m, path)
    d = json.loads(path.read_text())
    assert d["format"] == "endocal-model" and d["version"] == 2 and d["base"] == case[0]
    assert [e["name"] for e in d["effects"]] == list(case[1])
    m2 = load_model(path)
    for r in runs:
        assert np.max(np.abs(m2.predict(r.cmd_deg) - m.predict(r.cmd_deg))) <= 1e-12
    if u is not None:
        assert np.max(np.abs(m2.inverse(y_des) - u)) <= 1e-12
    assert str(m2) == str(m)
    # unfitted model refuses
    with pytest.raises(ModelError, match="not fitted"):
        make_model(case[0], list(case[1])).predict(runs[0].cmd_deg)
    with pytest.raises(ModelError, match="not fitted"):
        make_model(case[0], list(case[1])).inverse(runs[0].cmd_deg)


def test_every_base_is_in_the_contract():
    assert {c[0] for c in CASES} == set(BASES)


def test_settings_are_not_touched_by_fit(fitted):
    m = fitted[("pi", ("envelope",))]
    assert m.weights == "auto" and m.offset == "auto" and m.fixed is None
    assert m.structure_["weights"] == "exponential" and m.fixed_ == {"envelope_k1": 1.0}


def test_linear_falls_short_at_reversals_bspline_does_not():
    # The thesis: the piecewise-linear model fails at direction changes, B-splines do not.
    # Backlash-like data with gradual take-up after each reversal (a classic PI: plays
    # with spread thresholds), straight far from reversals, plus 0.3 deg noise.
    rng = np.random.default_rng(5)
    t = np.arange(0, 120, 0.05)
    u = 50 * np.sin(2 * np.pi * 0.05 * t) * (1 - 0.5 * (t > 60))
    truth = make_model("pi", weights="exponential", offset=False).set_parameters(
        {"pi_r": 1.5, "pi_w": 0.4, "pi_beta": 0.15})
    y_true = truth.predict(u)
    y = y_true + 0.3 * rng.standard_normal(u.size)
    du = np.diff(u, prepend=u[0])
    rev = np.flatnonzero(np.sign(du[2:]) * np.sign(du[1:-1]) < 0) + 1
    near_rev = np.zeros(u.size, dtype=bool)
    for k in rev:
        near_rev[k:k + 60] = True  # 3 s after each reversal: the take-up
    err = {b: np.abs(make_model(b).fit(u, y).predict(u) - y_true) for b in ("linear", "bspline")}
    rms = {b: (np.sqrt(np.mean(e[near_rev] ** 2)), np.sqrt(np.mean(e[~near_rev] ** 2))) for b, e in err.items()}
    # linear is worse at reversals (its straight branches and sharp switch miss the
    # curved take-up; measured ratio 1.6 with this seed), and worse overall
    assert rms["linear"][0] > 1.3 * rms["bspline"][0]
    assert np.sqrt(np.mean(err["bspline"] ** 2)) < np.sqrt(np.mean(err["linear"] ** 2))


def test_bspline_branches_rise_where_few_samples_lie_on_them():
    # A decaying sine through a 4 deg play: just after each reversal the output is on the
    # transition, so the low end of the up branch (and the high end of the down branch) has
    # almost no samples. Unconstrained, the fit let the up branch fall there (c0 > c1), and
    # the numerical inverse then failed on the model's own prediction. Fitted as first
    # coefficient plus non-negative increments, both branches rise, and the inverse of the
    # model's prediction replays it exactly.
    t = np.arange(0, 60, 0.05)
    u = 40 * np.sin(2 * np.pi * 0.05 * t) * (1 - t / 120)
    y = np.empty_like(u)
    z = 0.0
    for i, ui in enumerate(u):
        z = min(max(z, ui - 4), ui + 4)
        y[i] = 0.9 * z - 1e-4 * z**3
    y += 0.2 * np.random.default_rng(0).standard_normal(u.size)
    m = make_model("bspline", n_knots=4).fit(HysteresisData(cmd_deg=u, meas_deg=y, t_s=t))
    for branch in m._coefs(m.structure_, {k.removeprefix("bspline_"): v for k, v in m.params_.items()}):
        assert np.all(np.diff(branch) >= 0.0)
    y_model = m.predict(u)
    assert np.max(np.abs(m.predict(m.inverse(y_model)) - y_model)) < 1e-9


def test_a_hold_at_the_start_puts_no_knot_at_the_end_of_the_range():
    # A record that begins with the knob held at 0 (float noise of 1e-8 deg on the hold) and then
    # sweeps 0 -> 45 -> 0: counting the hold's samples put a quantile knot 4.5e-8 deg from the
    # end, an interval only the hold lay in, and the fitted branch jumped there (-16.8 deg at 0,
    # -5.4 deg at 3e-5). Knots come from the moving command, a quarter of an even step apart.
    rng = np.random.default_rng(3)
    hold = np.abs(1e-8 * rng.standard_normal(800))
    sweep = 45 * 0.5 * (1 - np.cos(2 * np.pi * np.arange(1500) / 1500))
    u = np.concatenate([hold, sweep])
    y = np.where(np.diff(u, prepend=0.0) >= 0, 0.9 * u - 3, 0.9 * u + 3) + 0.3 * rng.standard_normal(u.size)
    y[:800] = -5.6 + 0.3 * rng.standard_normal(800)  # the tip still bent from the last acquisition
    m = make_model("bspline").fit(HysteresisData(cmd_deg=u, meas_deg=y, t_s=np.arange(u.size) / 100.0))
    t = np.asarray(m.structure_["knots"])
    inner = t[m.structure_["degree"] + 1:-m.structure_["degree"] - 1]
    assert np.all(np.diff(np.concatenate([[0.0], inner, [t[-1]]])) >= 0.25 * 45 / 7 - 1e-9), inner
    p = {k.removeprefix("bspline_"): v for k, v in m.params_.items()}
    lo, up = m._eval_branches(m.structure_, p, np.array([0.0, 3e-5]))
    assert abs(lo[1] - lo[0]) < 0.01 and abs(up[1] - up[0]) < 0.01


def test_a_value_the_data_do_not_pin_down_is_said_in_words():
    import math

    from endocal.models.params import fmt_value

    assert fmt_value(0.11834, 0.0021) == "0.1183+-0.0021"
    assert fmt_value(-2.459, math.inf, "deg") == "-2.459 deg (not identified)"  # was "-2.459+-inf deg"


def _tendon_sheath_sweep(rng):
    """One sweep 0 -> +60 -> -60 -> 0 deg in 20 s at 100 Hz through a plant none of the models is:
    a capstan play of 2.8 deg, a 50 ms first-order lag of the distal section, a quadratic stiffening
    and 0.15 deg of sensor noise (a tendon-sheath bench; the plant of the red-team case)."""
    t = np.arange(0.0, 20.0, 0.01)
    u = 60.0 * np.sin(2.0 * np.pi * t / 20.0)
    p = np.empty_like(u)
    x = 0.0
    for i, ui in enumerate(u):
        x = min(max(x, ui - 2.8), ui + 2.8)
        p[i] = x
    y = np.zeros_like(p)
    a = 1.0 / (1.0 + 0.05 / 0.01)
    for i in range(1, p.size):
        y[i] = y[i - 1] + a * (p[i] - y[i - 1])
    meas = 0.78 * y + 4e-4 * np.sign(y) * y ** 2 + 0.15 * rng.standard_normal(u.size)
    return HysteresisData(cmd_deg=u, meas_deg=meas, t_s=t)


def test_a_fit_from_a_smaller_model_is_never_worse_than_that_model(monkeypatch):
    """`fit_from` (validate's candidates, `fit --start-from`): `pi` + `delay` + `envelope` nests
    `pi` + `delay` (an envelope of equal slopes is no envelope), so its fit cannot be worse on the
    same data. From `pi` + `delay`'s values the least squares stopped in a local minimum worse than
    `pi` + `delay` (here 0.213 vs 0.204 deg; on the 1 kHz record 0.231 vs 0.204, and validate
    ranked the envelope the plant has as making things 17 % worse); the fit from scratch reaches
    the plant's noise (0.154 deg against 0.15)."""
    d = _tendon_sheath_sweep(np.random.default_rng(3))
    smaller = make_model("pi", ["delay"], axis="ap").fit(d)
    warm_only = make_model("pi", ["delay", "envelope"], axis="ap").fit(d, warm_start=dict(smaller.params_))
    assert warm_only.fit_report_.rmse_deg > smaller.fit_report_.rmse_deg  # the local minimum this guards against
    bigger = make_model("pi", ["delay", "envelope"], axis="ap").fit_from(smaller, d)
    assert bigger.fit_report_.rmse_deg <= smaller.fit_report_.rmse_deg
    assert bigger.fit_report_.rmse_deg < 1.1 * 0.15  # the noise, +10 % for 9 parameters and a lag that is no delay
    assert "local minimum" in bigger.fit_report_.warnings[0]
    # dropping an effect nests nothing: a fit worse than the bigger model is no local minimum, and
    # is not fitted a second time from scratch
    back = make_model("pi", ["delay"], axis="ap")
    fits = []
    fit = type(back).fit
    monkeypatch.setattr(type(back), "fit", lambda self, *a, **k: fits.append(1) or fit(self, *a, **k))
    back.fit_from(bigger, d)
    assert back.fit_report_.rmse_deg > bigger.fit_report_.rmse_deg and len(fits) == 1


@pytest.mark.parametrize("base", ["linear", "bspline"])
def test_a_held_target_holds_the_command(data, base):
    """A direction-dependent model with a flat backlash band (transition slope 0, as fits of slack
    reach): a rounding error of 1e-15 deg in the present output sent the inverse across the band,
    and a held target made the command jump between the branches every sample (17.8 deg at 100 Hz
    on the demo's B-spline, played by `excite --model` while the other knob held still)."""
    runs, _ = data
    m = make_model(base, axis="lr", fixed={f"{base}_transition_slope": 0.0}).fit(runs)
    y_des = m.predict(0.8 * runs[0].cmd_deg)
    for held in (0.0, float(y_des[299])):
        y = np.concatenate([y_des[:300], np.full(300, held)])
        u = m.inverse(y)
        assert np.ptp(u[301:]) < 1e-9, np.unique(np.round(u[301:], 6))
        assert np.max(np.abs(m.predict(u) - y)) < 1e-8
