"""Effects compose onto any base: drift as an output term, fitted jointly, printed, saved."""

import numpy as np
import pytest

from endocal.errors import ModelError
from endocal.models import HysteresisData, load_model, make_model, save_model
from endocal.models.effects import make_effect
from tests._models_signals import PAPER_TABLE1, damped_sine


@pytest.fixture(scope="module")
def drifting():
    rng = np.random.default_rng(9)
    t, u = damped_sine(dt_s=0.05)
    truth = make_model("pi", ["envelope", "drift"]).set_parameters({**PAPER_TABLE1, "drift_rate_dps": 0.02})
    y = truth.predict(HysteresisData(cmd_deg=u, t_s=t)) + 0.3 * rng.standard_normal(u.size)
    return HysteresisData(cmd_deg=u, meas_deg=y, t_s=t), truth


@pytest.mark.parametrize("base", ["linear", "bspline", "pi"])
def test_drift_is_recovered_on_every_base(base, drifting, tmp_path):
    data, truth = drifting
    m = make_model(base, ["envelope", "drift"] if base == "pi" else ["drift"]).fit(data)
    rate, se = m.params_["drift_rate_dps"], m.stderr_["drift_rate_dps"]
    if base == "pi":  # the true model class: unbiased within a few standard errors
        assert abs(rate - 0.02) < 4 * se
        assert m.fit_report_.rmse_deg == pytest.approx(0.3, abs=0.02)
    else:
        # approximate bases see the drift too, but on the damped sine amplitude falls
        # with time, so a flexible branch shape absorbs part of it: only the sign and
        # order of magnitude are identified
        assert 0.005 < rate < 0.03
    assert "drift[" in str(m)
    # the drift term is removed by the inverse: the model output follows the desired angle
    y_des = m.predict(HysteresisData(cmd_deg=0.8 * data.cmd_deg, t_s=data.t_s))
    u = m.inverse(y_des, t_s=data.t_s)
    assert np.max(np.abs(m.predict(u, t_s=data.t_s) - y_des)) < 1e-8
    save_model(m, tmp_path / "m.json")
    assert np.max(np.abs(load_model(tmp_path / "m.json").predict(data.cmd_deg, t_s=data.t_s)
                         - m.predict(data.cmd_deg, t_s=data.t_s))) <= 1e-12


def test_missing_drift_shows_in_error(drifting):
    data, _ = drifting
    without = make_model("pi", ["envelope"]).fit(data)
    with_drift = make_model("pi", ["envelope", "drift"]).fit(data)
    assert with_drift.fit_report_.rmse_deg < 0.5 * without.fit_report_.rmse_deg


def test_effect_needs_time_and_zero_terms_are_dropped():
    _, u = damped_sine(dt_s=0.2)
    with pytest.raises(ModelError, match="drift' needs time stamps"):
        make_model("linear", ["drift"]).fit(u, u)
    m = make_model("linear", ["drift"]).set_parameters({
        "linear_up_slope": 1.0, "linear_up_offset_deg": -1.0, "linear_down_slope": 1.0,
        "linear_down_offset_deg": 1.0, "linear_transition_slope": 0.0, "drift_rate_dps": 0.0})
    assert "drift" not in m.equation()


def test_effect_catalog_entries_are_documented():
    for name in ("envelope", "drift"):
        e = make_effect(name)
        assert e.cause and e.signature and e.protocol
    with pytest.raises(ModelError, match="takes no ':' argument"):
        make_effect("drift:foo")


def test_slack_term_reproduces_the_simulators_tendon_slack_once_the_lag_is_modelled():
    # Ground truth from the simulator's capstan physics (not from the effect's own equations):
    # 1.5 mm of slack per tendon, default servo (2 x 30 ms) and tracker (15 ms) lag, no tracker
    # noise, so there is no floor. The slack operator plus `delay` on the B-spline must explain
    # the run almost exactly; without the slack term the plateaus at the neutral bend stay.
    import pandas as pd

    from endocal.probe import PRESETS
    from endocal.protocols import load_protocol
    from endocal.runs.aligned import align
    from endocal.sim import SimConfig, Simulator

    tee = PRESETS["tee"]
    cfg = SimConfig.default().replace(tracker={"noise_mm": 0.0, "orientation_noise_deg": 0.0})
    traj = load_protocol("damped-sine").trajectory(tee, seed=0)
    chunk = Simulator(cfg, tee, seed=0).execute(traj.t_s, traj.goal)
    df = align(pd.DataFrame(chunk.motor), pd.DataFrame(chunk.tracker), tee).table.iloc[::5]
    data = HysteresisData(cmd_deg=df["ap_cmd_deg"].to_numpy(), meas_deg=df["ap_meas_deg"].to_numpy(),
                          t_s=df["t_s"].to_numpy())
    with_slack = make_model("bspline", ["delay", "deadzone"]).fit(data)
    without = make_model("bspline", ["delay"]).fit(data)
    # 0.1 deg: a tenth of the tracker's noise floor (0.33 deg); the fit reaches ~0.02 deg
    assert with_slack.fit_report_.rmse_deg < 0.1 < 0.5 < without.fit_report_.rmse_deg
    # the play is the slack wound in across neutral: 2 x 1.5 mm on a 10 mm pulley = 17 deg of knob,
    # less the pretension stretch (2 x 0.5 mm), so ~11.5 deg; and the lag is ~80 ms
    assert 2 * with_slack.params_["deadzone_slack_deg"] == pytest.approx(11.5, abs=1.0)
    assert with_slack.params_["delay_s"] == pytest.approx(0.08, abs=0.01)


def test_rate_inverse_is_exact_where_the_drive_can_follow_and_bounded_where_it_cannot():
    # Parameters as fitted on the simulator's hidden-rate chirp: at 0.4 Hz and 45 deg the knob's
    # own speed (113 deg/s) raises the friction e^{0.0119 * 113} = 3.8-fold.
    from endocal.models.effects.rate import Rate

    t = np.arange(0.0, 20.0, 0.01)
    rate = Rate()
    p = {"gain_s": 0.0078, "amp_s_per_deg": 0.00082, "capstan_s_per_deg": 0.0119}

    def drive(u):
        return rate.apply(p, u, HysteresisData(cmd_deg=u, t_s=t))

    v = drive(45.0 * np.sin(2 * np.pi * 0.4 * t))  # a drive motion the knob can produce
    u = rate.invert(p, v, HysteresisData(cmd_deg=v, t_s=t))
    assert np.max(np.abs(drive(u) - v)) < 1e-9
    # twice as fast: the friction the knob's speed adds outgrows its travel, the drive cannot
    # follow; the inverse stays finite and within the commanded range instead of diverging
    fast = 45.0 * np.sin(2 * np.pi * 0.8 * t)
    u = rate.invert(p, fast, HysteresisData(cmd_deg=fast, t_s=t))
    assert np.all(np.isfinite(u)) and np.max(np.abs(u)) <= 46.0
    assert np.sqrt(np.mean((drive(u) - fast) ** 2)) <= np.sqrt(np.mean((drive(fast) - fast) ** 2))
