"""Bad input to the models: one clear ModelError each."""

import warnings

import numpy as np
import pytest

from endocal.errors import ModelError
from endocal.models import HysteresisData, OutOfRangeWarning, PIModel, make_model
from tests._models_signals import PAPER_TABLE1, damped_sine


@pytest.fixture(scope="module")
def fitted():
    rng = np.random.default_rng(0)
    _, u = damped_sine(amp_deg=40.0, dt_s=0.1)
    y = make_model("pi", ["envelope"]).set_parameters(PAPER_TABLE1).predict(u) + 0.3 * rng.standard_normal(u.size)
    return u, y, make_model("linear").fit(u, y)


def test_nan_and_inf_are_refused(fitted):
    u, y, m = fitted
    bad = u.copy()
    bad[7] = np.nan
    with pytest.raises(ModelError, match="cmd_deg contains NaN or inf .*first at index 7"):
        m.predict(bad)
    ybad = y.copy()
    ybad[3] = np.inf
    with pytest.raises(ModelError, match="meas_deg contains NaN or inf"):
        make_model("linear").fit(u, ybad)


def test_non_monotonic_time_is_refused():
    t = np.arange(100.0)
    t[50] = t[49]
    with pytest.raises(ModelError, match="t_s is not strictly increasing at sample 50"):
        HysteresisData(cmd_deg=np.zeros(100), t_s=t)


def test_too_few_samples():
    u = 10 * np.sin(np.linspace(0, 6 * np.pi, 40))
    with pytest.raises(ModelError, match="too few samples to fit"):
        make_model("pi", ["envelope"]).fit(u, u)


def test_no_reversal_means_no_backlash():
    u = np.linspace(-30, 30, 500)
    with pytest.raises(ModelError, match="backlash cannot be identified: the command never reverses"):
        make_model("bspline").fit(u, 0.5 * u)


def test_out_of_range_error_or_clamp(fitted):
    u, y, m = fitted
    with pytest.raises(ModelError, match="outside the fitted command range"):
        m.predict(1.5 * u)
    with pytest.raises(ModelError, match="outside the fitted command range"):
        m.inverse(3 * y)
    mc = make_model("linear", out_of_range="clamp").fit(u, y)
    with pytest.warns(OutOfRangeWarning, match="clamped"):
        out = mc.predict(1.5 * u)
    assert np.all(np.isfinite(out))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        mc.predict(u)  # in range: no warning


def test_settings_errors():
    _, u = damped_sine(dt_s=0.2)
    with pytest.raises(ModelError, match="out_of_range must be one of"):
        make_model("linear", out_of_range="ignore").fit(u, u)
    with pytest.raises(ModelError, match="unknown model 'lstm'"):
        make_model("lstm")
    with pytest.raises(ModelError, match="unknown effect 'magic'"):
        make_model("pi", ["magic"]).fit(u, u)
    with pytest.raises(ModelError, match="given twice"):
        make_model("pi", ["envelope", "envelope"]).fit(u, u)
    with pytest.raises(ModelError, match="weights must be one of"):
        PIModel(weights="random").fit(u, u)
    with pytest.raises(ModelError, match="fixed names unknown parameter"):
        make_model("linear", fixed={"pi_r": 1.0}).fit(u, np.sin(u))
    with pytest.raises(ModelError, match="needs the measured bending angle"):
        make_model("linear").fit(u)


def test_several_runs_restart_operator_state():
    m = make_model("pi", ["envelope"]).set_parameters(PAPER_TABLE1)
    _, u = damped_sine(dt_s=0.1)
    a, b = u[:300], u[300:]
    joint = m.predict([a, b])
    assert np.array_equal(joint[1], m.predict(b))  # not m.predict(u)[300:]
    assert not np.allclose(joint[1], m.predict(u)[300:])


def test_reversals_ignore_rounding_and_wiggles_but_count_each_turn():
    """A knob held still by an inverse model (its goal computed to ~1e-12 deg) does not reverse;
    a back-and-forth sweep with encoder noise reverses once per turn, as every command counts."""
    from endocal.models.data import reversals

    rng = np.random.default_rng(0)
    held = 1e-12 * rng.standard_normal(2000)
    assert reversals(held) == 0
    t = np.linspace(0.0, 1.0, 2001)
    sweep = 40.0 * np.sin(2 * np.pi * t) + 0.05 * rng.standard_normal(t.size)  # 0 -> +40 -> -40 -> 0
    assert reversals(sweep) == 2
    d = HysteresisData(np.concatenate([sweep, sweep]), meas_deg=np.zeros(2 * t.size), run_starts=np.array([0, t.size]))
    assert d.n_reversals() == 4
