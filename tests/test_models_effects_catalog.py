"""The effect catalog (issue 5): each effect, fitted jointly with a base, explains data that has it.

Two kinds of data:

- ground truth: the paper's modified PI (table 1) with one effect of known size, plus
  0.3 deg of white noise (the noise floor). The bar of issue 5: refitting base + effect on
  the first 2/3 cuts the held-out RMSE on the last 1/3 by >= 50 % and brings it within
  1.5x the noise floor; on data without the effect, adding it gains < 5 %.
- the simulator (a capstan tendon-sheath model, not the model's equations), for the
  effects whose simulator physics the terms capture to the noise floor (see the notes
  at those tests for the others' numbers).

Every effect also round-trips through save/load exactly, prints its term, and inverts.
"""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from endocal.errors import ModelError
from endocal.models import HysteresisData, load_model, make_model, save_model
from endocal.models.effects import EFFECTS, catalog, make_effect
from tests._models_signals import PAPER_TABLE1

NOISE_DEG = 0.3
DT_S = 0.02

# effect name -> (spec, true parameters, text the equation must show)
TRUTH = {
    # the slack is centred on the neutral bend, the zero of the paper's envelope (theta1 = 3.73 deg)
    "deadzone": ("deadzone", {"deadzone_slack_deg": 4.0, "deadzone_band_deg": 6.0, "deadzone_center_deg": 3.7}, "slack("),
    # the same slack between the friction and the tip: 3 deg of bend, a band of 4 deg around a 2 deg bend
    "deadzone:tip": ("deadzone:tip", {"deadzone_tip_slack_deg": 3.0, "deadzone_tip_band_deg": 4.0,
                                      "deadzone_tip_center_deg": 2.0}, "tipslack("),
    # play of 0.03 s per deg/s at neutral, growing 1 %/deg with the knob angle (tension), and
    # e^{0.005 s/deg * 60 deg/s} - 1 = 35 % more than linear at the fastest knob speed (capstan)
    "rate": ("rate", {"rate_gain_s": 0.03, "rate_amp_s_per_deg": 0.0003, "rate_capstan_s_per_deg": 0.005},
             "rateplay("),
    "delay": ("delay", {"delay_s": 0.13}, "(t - tau)"),
    # 6 % of the bend as extra backlash: ~3.6 deg of knob at a 60 deg bend, ~0 near neutral
    "tension": ("tension", {"tension_friction": 0.06}, "tplay("),
    # the other half-bend 0.8 deg per deg of the other knob, lagging it by a 3 deg play; own half-planes
    # deviated by +8.5 and -11.3 deg
    "coupling": ("coupling", {"coupling_linear": 0.12, "coupling_abs": 0.06, "coupling_gain": 0.8,
                              "coupling_tilt_pos": -0.15, "coupling_tilt_neg": 0.2, "coupling_lag_deg": 3.0},
                 "coupling["),
    "creep": ("creep", {"creep_fraction": 0.25, "creep_tau_s": 2.0}, "creep("),
    "load": ("load:wrap_deg", {"load_wrap_deg_up": 0.05, "load_wrap_deg_down": 0.0, "load_wrap_deg_up_amp": 0.0005,
                               "load_wrap_deg_down_amp": 0.0, "load_wrap_deg_gain": -0.0005,
                               "load_wrap_deg_lo": 100.0, "load_wrap_deg_hi": 200.0},
             "loadplay("),
}


def rich_command(seed=0):
    """Slow large sine, fast small sines, then a staircase with holds (deg), on a 50 Hz clock."""
    t = np.arange(0.0, 180.0, DT_S)
    u = np.where(t < 60, 60 * np.sin(2 * np.pi * 0.05 * t), 0.0)
    fast = (t >= 60) & (t < 120)
    u[fast] = 30 * np.sin(2 * np.pi * 0.4 * t[fast]) + 20 * np.sin(2 * np.pi * 0.09 * t[fast])
    levels = np.random.default_rng(seed).uniform(-55, 55, 16)
    stair = t >= 120
    u[stair] = levels[((t[stair] - 120) / 3.75).astype(int).clip(0, 15)]
    # the knob moves between levels at most 60 deg/s
    out = u.copy()
    for k in range(1, u.size):
        out[k] = out[k - 1] + np.clip(u[k] - out[k - 1], -60 * DT_S, 60 * DT_S)
    extras = {"other_cmd_deg": 40 * np.sin(2 * np.pi * 0.031 * t + 1.0),
              "wrap_deg": 150 + 50 * np.sin(2 * np.pi * t / 70.0)}
    return t, out, extras


def synthetic(effect: str | None, seed=1):
    t, u, extras = rich_command()
    specs, values = ["envelope"], dict(PAPER_TABLE1)
    if effect is not None:
        spec, p, _ = TRUTH[effect]
        specs.append(spec)
        values.update(p)
    truth = make_model("pi", specs).set_parameters(values)
    y = truth.predict(HysteresisData(cmd_deg=u, t_s=t, extras=extras))
    y = y + NOISE_DEG * np.random.default_rng(seed).standard_normal(u.size)
    return HysteresisData(cmd_deg=u, meas_deg=y, t_s=t, extras=extras)


def split(d: HysteresisData, frac=2 / 3):
    k = int(frac * d.n_samples)

    def part(sl):
        return HysteresisData(cmd_deg=d.cmd_deg[sl], meas_deg=d.meas_deg[sl], t_s=d.t_s[sl],
                              extras={c: v[sl] for c, v in d.extras.items()})

    return part(slice(0, k)), part(slice(k, None))


def heldout_rmse(base, specs, d):
    """Fit on the first 2/3, RMSE on the last 1/3 (predicted through the whole record, so the
    operators carry their state into the held-out part as the data's did)."""
    train, _ = split(d)
    m = make_model(base, specs).fit(train)
    k = train.n_samples
    r = (m.predict(d) - d.meas_deg)[k:]
    return float(np.sqrt(np.mean(r ** 2))), m


@pytest.fixture(scope="module")
def clean():
    return synthetic(None)


@pytest.fixture(scope="module")
def clean_without(clean):
    """The held-out RMSE of the paper's model (pi + envelope) on ``clean``: the bar of every effect's test."""
    return heldout_rmse("pi", ["envelope"], clean)[0]


# ------------------------------------------------------------------ catalog
def test_catalog_lists_every_effect_with_its_physics():
    names = [e.name for e in catalog()]
    assert names == list(EFFECTS)
    assert {"envelope", "deadzone", "tension", "rate", "delay", "coupling", "drift", "creep", "load"} <= set(names)
    for e in catalog():
        assert e.cause and e.signature and e.protocol and e.parameters


def test_effect_names_parse_and_bad_names_fail():
    assert make_effect("load:sheath_wrap_deg").label == "load:sheath_wrap_deg"
    assert make_effect("load:sheath_wrap_deg").full_names() == [
        "load_sheath_wrap_deg_up", "load_sheath_wrap_deg_down", "load_sheath_wrap_deg_up_amp",
        "load_sheath_wrap_deg_down_amp", "load_sheath_wrap_deg_gain", "load_sheath_wrap_deg_lo",
        "load_sheath_wrap_deg_hi"]
    assert make_effect("coupling:ml_meas_deg").column == "ml_meas_deg"
    with pytest.raises(ModelError, match="load needs a column"):
        make_effect("load")
    with pytest.raises(ModelError, match="nothing after"):
        make_effect("load:")
    with pytest.raises(ModelError, match="takes no ':' argument"):
        make_effect("delay:foo")
    with pytest.raises(ModelError, match="unknown effect"):
        make_effect("hysteria")


def test_load_refuses_a_missing_or_constant_column(clean):
    with pytest.raises(ModelError, match="no column 'bogus'"):
        make_model("pi", ["envelope", "load:bogus"]).fit(clean)
    flat = HysteresisData(cmd_deg=clean.cmd_deg, meas_deg=clean.meas_deg, t_s=clean.t_s,
                          extras={"wrap_deg": np.full(clean.n_samples, 3.0)})
    with pytest.raises(ModelError, match="'wrap_deg' is constant"):
        make_model("pi", ["envelope", "load:wrap_deg"]).fit(flat)
    with pytest.raises(ModelError, match="other_cmd_deg"):
        make_model("pi", ["envelope", "coupling"]).fit(HysteresisData(cmd_deg=clean.cmd_deg, meas_deg=clean.meas_deg,
                                                                      t_s=clean.t_s))
    with pytest.raises(ModelError, match="needs time stamps"):
        make_model("pi", ["rate"]).fit(clean.cmd_deg, clean.meas_deg)


# ------------------------------------------------------------------ ground truth
@pytest.mark.parametrize("effect", list(TRUTH))
def test_effect_explains_data_that_has_it(effect, tmp_path):
    d = synthetic(effect)
    spec, _, shown = TRUTH[effect]
    without, _ = heldout_rmse("pi", ["envelope"], d)
    with_it, m = heldout_rmse("pi", ["envelope", spec], d)
    assert with_it <= 0.5 * without, (without, with_it)
    assert with_it <= 1.5 * NOISE_DEG, (without, with_it)
    assert shown in str(m)
    # save / load: predictions and inverse exactly the same
    save_model(m, tmp_path / "m.json")
    m2 = load_model(tmp_path / "m.json")
    assert np.max(np.abs(m2.predict(d) - m.predict(d))) <= 1e-12
    assert str(m2) == str(m)
    # inverse: the model's own output of a smaller motion is reached
    small = HysteresisData(cmd_deg=0.8 * d.cmd_deg, t_s=d.t_s, extras=d.extras)
    y_des = m.predict(small)
    u = m.inverse(y_des, t_s=d.t_s, extras=d.extras)
    err = np.abs(m.predict(HysteresisData(cmd_deg=u, t_s=d.t_s, extras=d.extras)) - y_des)
    if effect == "delay":
        # a sub-sample time shift undone by a time advance: the two linear interpolations
        # leave f(1-f) dt |Δslope| <= dt |Δslope| / 4 at each kink of the trajectory (a
        # reversal, a corner of the staircase), dt² |ÿ| / 4 on smooth parts; a tenth of
        # the noise floor in RMS
        slope = np.diff(y_des) / DT_S
        assert np.max(err) <= DT_S * np.max(np.abs(np.diff(slope))) / 4
        assert np.sqrt(np.mean(err ** 2)) < 0.1 * NOISE_DEG
    else:
        assert np.max(err) < 1e-8
    assert np.max(np.abs(m2.inverse(y_des, t_s=d.t_s, extras=d.extras) - u)) <= 1e-12


@pytest.mark.parametrize("effect", list(TRUTH))
def test_effect_gains_nothing_on_data_without_it(effect, clean, clean_without):
    without = clean_without
    with_it, _ = heldout_rmse("pi", ["envelope", TRUTH[effect][0]], clean)
    assert with_it > 0.95 * without, (without, with_it)


@pytest.mark.parametrize("base", ["linear", "bspline"])
def test_effects_compose_onto_the_other_bases(base):
    d = synthetic("delay").decimate(2)
    without, _ = heldout_rmse(base, ["envelope"], d)
    with_it, m = heldout_rmse(base, ["envelope", "delay"], d)
    assert with_it < 0.6 * without
    assert m.params_["delay_s"] == pytest.approx(0.13, abs=0.02)


def test_parameters_are_recovered():
    d = synthetic("creep")
    m = make_model("pi", ["envelope", "creep"]).fit(d)
    # 9000 samples at 0.3 deg noise: standard errors of a few 1e-3; allow 5 of them
    for name, true in TRUTH["creep"][1].items():
        assert abs(m.params_[name] - true) < max(5 * m.stderr_[name], 0.02 * abs(true)), name
    d = synthetic("deadzone")
    m = make_model("pi", ["envelope", "deadzone"]).fit(d)
    assert m.params_["deadzone_slack_deg"] == pytest.approx(4.0, abs=0.3)


def test_the_slack_is_placed_on_its_side_of_the_friction():
    """The slack between the friction and the tip (deg of bend) is recovered within five standard errors
    (2026-11-29: within two), and the same slack on the knob's side cannot stand in for it, even on a base with
    return-point memory: 0.74 deg against the noise's 0.30."""
    d = synthetic("deadzone:tip")
    m = make_model("pi", ["envelope", "deadzone:tip"]).fit(d)
    for name, true in TRUTH["deadzone:tip"][1].items():
        assert abs(m.params_[name] - true) < max(5 * m.stderr_[name], 0.02 * abs(true)), name
    knob = make_model("pi", ["envelope", "deadzone"]).fit(d)
    rmse = [float(np.sqrt(np.mean((x.predict(d) - d.meas_deg) ** 2))) for x in (m, knob)]
    assert rmse[0] < 1.05 * NOISE_DEG and rmse[1] > 2 * NOISE_DEG, rmse


def test_the_other_bends_lag_is_recovered_and_matters():
    """The other bend lags its knob by a 3 deg play (TRUTH): the fit finds it within five standard errors, and
    the coupling without the lag (the form before it) leaves the two bends' loops in the residual."""
    d = synthetic("coupling")
    m = make_model("pi", ["envelope", "coupling"]).fit(d)
    assert abs(m.params_["coupling_lag_deg"] - 3.0) < max(5 * m.stderr_["coupling_lag_deg"], 0.1)
    without = make_model("pi", ["envelope", EFFECTS["coupling"](lag="none")]).fit(d)
    rmse = [float(np.sqrt(np.mean((x.predict(d) - d.meas_deg) ** 2))) for x in (m, without)]
    # with the lag: the noise (0.299 deg, 2026-11-28); without it: 0.586, twice the noise
    assert rmse[0] < 1.05 * NOISE_DEG < rmse[1] / 1.1, rmse


def test_a_coupling_model_file_written_before_the_lag_loads_as_it_was_fitted(tmp_path):
    d = synthetic("coupling")
    old = make_model("pi", ["envelope", EFFECTS["coupling"](lag="none")]).fit(d)
    path = tmp_path / "old.json"
    save_model(old, path)
    doc = json.loads(path.read_text())
    entry = next(e for e in doc["effects"] if e["name"] == "coupling")
    del entry["settings"]["lag"]  # as the files before it were written
    path.write_text(json.dumps(doc))
    back = load_model(path)
    assert "coupling_lag_deg" not in back.params_
    assert np.max(np.abs(back.predict(d) - old.predict(d))) <= 1e-12


def test_streaming_compensator_matches_the_batch_inverse_or_refuses():
    for effect in ("deadzone", "deadzone:tip", "tension", "rate", "creep"):  # the last one needs the sample period
        d = synthetic(effect)
        spec, values, _ = TRUTH[effect]
        m = make_model("pi", ["envelope", spec]).set_parameters({**PAPER_TABLE1, **values}, cmd_range_deg=(-70, 70))
        y_des = m.predict(HysteresisData(cmd_deg=0.8 * d.cmd_deg, t_s=d.t_s))
        u = m.inverse(y_des, t_s=d.t_s)
        comp = m.compensator(dt_s=DT_S)
        streamed = np.array([comp.step(v) for v in y_des[:3000]])
        assert np.max(np.abs(streamed - u[:3000])) < 1e-9, effect
    with pytest.raises(ModelError, match="give dt_s"):
        m.compensator()
    for effect in ("delay", "load", "coupling"):
        spec, values, _ = TRUTH[effect]
        m = make_model("pi", ["envelope", spec]).set_parameters({**PAPER_TABLE1, **values})
        with pytest.raises(ModelError, match="cannot be compensated one sample at a time"):
            m.compensator(dt_s=DT_S)


# ------------------------------------------------------------------ simulator
def _simulate(cfg, ap, ml=None, seed=0, fs_hz=100.0):
    from endocal.probe import PRESETS
    from endocal.runs.aligned import align
    from endocal.sim import Simulator

    tee = PRESETS["tee"]
    t = np.arange(ap.size) / fs_hz
    goal = {dof: np.zeros(ap.size) for dof in tee.dofs}
    goal["ap"] = ap
    if ml is not None:
        goal["ml"] = ml
    c = Simulator(cfg, tee, seed=seed).execute(t, goal)
    al = align(pd.DataFrame(c.motor), pd.DataFrame(c.tracker), tee).table
    ts = al["t_s"].to_numpy()
    d = HysteresisData(cmd_deg=al["ap_cmd_deg"].to_numpy(), meas_deg=al["ap_meas_deg"].to_numpy(), t_s=ts,
                       extras={"other_cmd_deg": al["ml_cmd_deg"].to_numpy()})
    # the noise floor: measured minus the simulator's true angle at the same instant
    floor = float(np.sqrt(np.mean((d.meas_deg - np.interp(ts, c.truth["t_s"], c.truth["ap_true_deg"])) ** 2)))
    return d, floor


def _sim_config(**effects):
    from endocal.sim import SimConfig

    # servo and tracker with no lag of their own (a servo lag is a delay the delay test
    # covers), tendons without slack unless the test is about it
    base = SimConfig.default().replace(motor={"knob_time_constant_s": 0.0}, tracker={"latency_s": 0.0},
                                       deadzone={"enabled": False})
    return base.replace(**effects)


def _multisine(duration_s=150.0, fs_hz=100.0):
    t = np.arange(int(duration_s * fs_hz)) / fs_hz
    return 35 * np.sin(2 * np.pi * 0.03 * t) + 20 * np.sin(2 * np.pi * 0.071 * t + 1) + 8 * np.sin(2 * np.pi * 0.13 * t + 2)


def test_simulator_tendon_slack_is_explained_by_deadzone():
    # The modified PI with `tension`: the simulator's capstan friction grows with the bend,
    # which congruent PI loops cannot shape (as in the compensation test); without it the
    # slack term also takes up part of that misfit (-10 % on data without slack).
    u = _multisine()
    model = ["envelope", "tension"]
    d, floor = _simulate(_sim_config(deadzone={"enabled": True}), u)
    without, _ = heldout_rmse("pi", model, d)
    with_it, m = heldout_rmse("pi", model + ["deadzone"], d)
    # the simulator's 1.5 mm slack minus 0.53 mm pretension stretch, per tendon, through a
    # 10 mm pulley: 5.5 deg of knob play on each side
    assert m.params_["deadzone_slack_deg"] == pytest.approx(5.5, abs=1.0)
    assert with_it <= 0.5 * without and with_it <= 1.5 * floor, (without, with_it, floor)
    # on data without slack the term gains less than validate's 10 % bar for a suspect (~4 %)
    d0, _ = _simulate(_sim_config(), u)
    assert heldout_rmse("pi", model + ["deadzone"], d0)[0] > 0.9 * heldout_rmse("pi", model, d0)[0]


def test_simulator_latency_is_explained_by_delay():
    # bspline: its branches follow the capstan loop closer than the PI's (0.04 vs 0.39 deg
    # on noise-free data), which leaves room under the 1.5x noise-floor bar
    u = _multisine()
    d, floor = _simulate(_sim_config(delay={"enabled": True, "latency_s": 0.15}), u)
    without, _ = heldout_rmse("bspline", ["envelope"], d)
    with_it, m = heldout_rmse("bspline", ["envelope", "delay"], d)
    # the floor against the true angle includes the latency itself; against the true
    # angle 0.15 s earlier it is the tracker noise, ~0.34 deg
    assert m.params_["delay_s"] == pytest.approx(0.15, abs=0.02)
    assert with_it <= 0.5 * without and with_it <= 1.5 * 0.37, (without, with_it, floor)
    d0, _ = _simulate(_sim_config(), u)
    assert heldout_rmse("bspline", ["envelope", "delay"], d0)[0] > 0.95 * heldout_rmse("bspline", ["envelope"], d0)[0]


def test_coupling_fit_on_a_whole_circle_run_does_not_stall():
    # Both knobs on the protocol's circle (3 turns, 7000 samples, the simulator's default servo
    # and tracker lag), fitted on every sample: from the planes' nominal directions alone the
    # fit stalled where the B-spline had bent its branches to mimic the coupling (3.6 deg, 9x
    # the floor, on this seed). Fitted from the best of the coupling's start candidates it
    # explains the run to 1.15x the floor in-sample (the ~80 ms lag the model lacks and the
    # capstan transitions are the rest), so 1.4x separates the two by far.
    from endocal.probe import PRESETS
    from endocal.protocols import load_protocol
    from endocal.sim import SimConfig

    traj = load_protocol("circle").trajectory(PRESETS["tee"], seed=1)
    cfg = SimConfig.default().replace(deadzone={"enabled": False}, coupling={"enabled": True})
    d, floor = _simulate(cfg, traj.goal["ap"], traj.goal["ml"], seed=1)
    m = make_model("bspline", ["coupling"]).fit(d)
    assert m.fit_report_.rmse_deg <= 1.4 * floor, (m.fit_report_.rmse_deg, floor)
